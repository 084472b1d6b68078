"""The docs site builds strictly, offline: a broken link, a missing anchor, a page missing from
the nav, a dangling cross-reference or a docstring griffe cannot read fails the build."""

from __future__ import annotations

import doctest
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from ._hooks import ROOT, load_hook

pytest.importorskip("mkdocs", reason="the docs extra is not installed: pip install -e '.[docs]'")


def test_the_site_builds_strictly_without_warnings(tmp_path: Path) -> None:
    site = tmp_path / "site"
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", "mkdocs.yml", "-d", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    assert "WARNING" not in result.stderr, result.stderr[-4000:]
    env_page = (site / "api" / "envs" / "index.html").read_text()
    assert 'id="oasis_torchrl.envs.oasis_env.OasisEnv"' in env_page
    # Docstrings' doctest lines render as code, not as prose.
    assert '<span class="gp">&gt;&gt;&gt; </span>' in env_page
    assert ":class:" not in env_page
    assert (site / "benchmarks" / "index.html").stat().st_size > 0


def test_the_site_loads_nothing_from_the_network(tmp_path: Path) -> None:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    assert config["theme"]["font"] is False
    handler = config["plugins"][1]["mkdocstrings"]["handlers"]["python"]
    assert "inventories" not in handler


def test_every_page_under_docs_is_in_the_nav() -> None:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())

    def pages(entries: list) -> list[str]:
        found = []
        for entry in entries:
            value = next(iter(entry.values())) if isinstance(entry, dict) else entry
            found += pages(value) if isinstance(value, list) else [value]
        return found

    in_nav = set(pages(config["nav"]))
    on_disk = {
        str(path.relative_to(ROOT / "docs"))
        for path in (ROOT / "docs").rglob("*.md")
        if "_hooks" not in path.parts
    }
    assert on_disk <= in_nav, sorted(on_disk - in_nav)


def test_the_hooks_examples_run() -> None:
    for name in ("docstring_markdown", "api_pages"):
        failures, tried = doctest.testmod(load_hook(name))
        assert tried > 0 and failures == 0, name


def test_doctest_lines_are_fenced_and_fences_left_alone() -> None:
    fence = load_hook("docstring_markdown").fence_doctests
    source = ["```python", ">>> inside", "```", "", "    >>> indented", "", ">>> a[0]", "1"]
    fenced = fence(source)
    assert fenced[:6] == source[:6]
    assert fenced[6:] == ["", "```pycon", ">>> a[0]", "1", "```"]


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_the_built_site_is_ignored_by_git() -> None:
    result = subprocess.run(["git", "check-ignore", "-q", "site/index.html"], cwd=ROOT, check=False)
    assert result.returncode == 0
