"""The Markdown reads the same on a forge as on the site: every relative link of the README and
of ``docs/`` names a file that exists in the repository (the generated API pages exist only on
the site, so the guides link to the source, which the site's hook points at the API pages), and
the getting-started page's quick start is the README's."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from ._hooks import ROOT

LINK = re.compile(r"\]\((?!https?://|#|mailto:)(?P<target>[^)#\s]+)")
FENCE = re.compile(r"^```.*?^```", re.DOTALL | re.MULTILINE)
QUICK_START = re.compile(r"<!-- quick-start -->\n```\w+\n.*?```", re.DOTALL)
PAGES = sorted(
    [ROOT / "README.md"]
    + [path for path in (ROOT / "docs").rglob("*.md") if "_hooks" not in path.parts]
)


def relative_links(page: Path) -> list[str]:
    """The relative link targets of a Markdown page, outside fenced code."""
    return [match["target"] for match in LINK.finditer(FENCE.sub("", page.read_text()))]


def test_the_link_pattern_skips_urls_anchors_and_code() -> None:
    text = "[a](guides/env.md#x) [b](https://x.org/y) [c](#here)\n```\n[d](gone.md)\n```\n"
    assert [m["target"] for m in LINK.finditer(FENCE.sub("", text))] == ["guides/env.md"]


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(ROOT)))
def test_every_relative_link_names_a_file_of_the_repository(page: Path) -> None:
    missing = [target for target in relative_links(page) if not (page.parent / target).exists()]
    assert not missing, f"{page.relative_to(ROOT)} links to what a forge cannot show: {missing}"


def test_the_getting_started_quick_start_is_the_readmes() -> None:
    readme = QUICK_START.findall((ROOT / "README.md").read_text())
    assert readme
    assert QUICK_START.findall((ROOT / "docs" / "getting_started.md").read_text()) == readme
