"""README.md: short, its quick start runs as written, its links resolve, and its env card is the
env's (and ``OasisEnv``'s docstring's)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from oasis_torchrl.drivers.pretrained import shipped_policies
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.train.cards import hours, load_card

from ._hooks import ROOT

README = (ROOT / "README.md").read_text()
BENCHMARKS = (ROOT / "BENCHMARKS.md").read_text()
FIGURE = re.compile(r"(?<![\w.])\d+\.\d+ ?(?:m|h|x|ms|s|%)(?!\w)")
"""A measured figure: a decimal number with its unit (metres, hours, a ratio, time, a share)."""
SHIPPED_TABLE = "<!-- shipped-policies -->\n"
QUICK_START = re.compile(r"<!-- quick-start -->\n```(?P<lang>\w+)\n(?P<code>.*?)```", re.DOTALL)
CARD_ROW = re.compile(
    r"^\s*\| `(?P<key>[^`]+)` \| `(?P<spec>[^`]+)` "
    r"\| `\[(?P<shape>[^\]]+)\]` \| `(?P<dtype>\w+)` \|$"
)


RETRAIN_ROW = "retrain it (wall time on 2 cores)"


def quick_start(lang: str) -> list[str]:
    return [m["code"] for m in QUICK_START.finditer(README) if m["lang"] == lang]


def command_env() -> dict[str, str]:
    """The environment a reader has after activating the venv: its scripts first on PATH."""
    scripts = str(Path(sys.executable).parent)
    return {**os.environ, "PATH": f"{scripts}{os.pathsep}{os.environ.get('PATH', '')}"}


def test_readme_is_at_most_250_lines() -> None:
    assert len(README.splitlines()) <= 250


def test_readme_links_resolve() -> None:
    targets = re.findall(r"\]\((?!https?://|#)([^)#]+)", README)
    assert targets
    missing = [target for target in targets if not (ROOT / target).exists()]
    assert not missing


def test_quick_start_python_runs_as_written(tmp_path: Path) -> None:
    blocks = quick_start("python")
    assert blocks, "README marks no python block as the quick start"
    for code in blocks:
        result = subprocess.run(
            [sys.executable, "-c", code],
            cwd=tmp_path,
            env=command_env(),
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert result.returncode == 0, result.stderr[-3000:]


def test_quick_start_commands_run_as_written(tmp_path: Path) -> None:
    lines = [line for code in quick_start("bash") for line in code.splitlines() if line.strip()]
    assert lines, "README marks no shell block as the quick start"
    for line in lines:
        result = subprocess.run(
            ["bash", "-c", line],
            cwd=tmp_path,
            env=command_env(),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert result.returncode == 0, f"{line}: {result.stderr[-2000:]}"
        assert result.stdout.strip(), line


def card_rows(text: str) -> list[re.Match[str]]:
    return [match for line in text.splitlines() if (match := CARD_ROW.match(line))]


def test_readme_card_is_the_env_docstring_card() -> None:
    readme = [match.group(0).strip() for match in card_rows(README)]
    docstring = [match.group(0).strip() for match in card_rows(OasisEnv.__doc__ or "")]
    assert readme and readme == docstring


@pytest.fixture(scope="module")
def small_env() -> OasisEnv:
    # Specs come from the layout: nothing is opened, so no server starts.
    return OasisEnv("local", num_envs=2, server=ServerConfig(width=96, height=64))


def test_env_card_matches_the_specs(small_env: OasisEnv) -> None:
    sizes = {"N": 2, "H": 64, "W": 96}
    specs = small_env.full_action_spec.clone().update(small_env.observation_spec)
    for row in card_rows(OasisEnv.__doc__ or ""):
        # ("pixels", camera): quoted parts are names, bare ones stand for every name there.
        pattern = tuple(part.strip() for part in row["key"].strip("()").split(","))
        keys = [
            key if isinstance(key, tuple) else (key,)
            for key in specs.keys(include_nested=True, leaves_only=True)
        ]
        matching = [
            key
            for key in keys
            if len(key) == len(pattern)
            and all(
                f'"{part}"' == want or not want.startswith('"')
                for part, want in zip(key, pattern, strict=True)
            )
        ]
        assert matching, row["key"]
        shape = tuple(int(sizes.get(dim, dim)) for dim in row["shape"].replace(" ", "").split(","))
        for key in matching:
            spec = specs[key]
            assert tuple(spec.shape) == shape, (key, spec.shape)
            assert spec.dtype == getattr(torch, row["dtype"]), (key, spec.dtype)
            bounded = re.fullmatch(r"Bounded\((?P<low>[-\d.]+), (?P<high>[-\d.]+)\)", row["spec"])
            if bounded:
                assert spec.space.low.min().item() == float(bounded["low"]), key
                assert spec.space.high.max().item() == float(bounded["high"]), key
            else:
                assert row["spec"] == "Unbounded" and "Unbounded" in type(spec).__name__, key


def section(text: str, heading: str) -> str:
    start = text.index(f"## {heading}\n")
    end = text.find("\n## ", start + 1)
    return text[start : end if end >= 0 else None]


def test_readme_and_docs_home_say_the_same_about_where_features_work() -> None:
    home = (ROOT / "docs" / "index.md").read_text()
    table = [
        line for line in section(README, "Where each feature works").splitlines() if "|" in line
    ]
    assert table
    assert table == [
        line for line in section(home, "Where each feature works").splitlines() if "|" in line
    ]


def table_cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def shipped_table(text: str) -> list[str]:
    """The lines of the shipped policies' table that follows its marker."""
    assert SHIPPED_TABLE in text
    return text.split(SHIPPED_TABLE, 1)[1].split("\n\n", 1)[0].splitlines()


def test_the_readme_quotes_the_shipped_policies_table_of_benchmarks() -> None:
    assert shipped_table(README) == shipped_table(BENCHMARKS)


@pytest.mark.parametrize("page", ["README.md", "docs/index.md"])
def test_every_figure_on_the_front_pages_is_one_of_benchmarks(page: str) -> None:
    """One figure, one place: a measured figure the README or the docs' home page gives is
    BENCHMARKS.md's, to the digit (a re-measured figure is changed there, then quoted)."""
    text = (ROOT / page).read_text()
    missing = sorted({figure for figure in FIGURE.findall(text) if figure not in BENCHMARKS})
    assert not missing, f"{page} gives figures BENCHMARKS.md does not: {missing}"


def test_the_figure_pattern_finds_figures() -> None:
    found = FIGURE.findall("310.0 m, **1.44x**, 2.7 h, 5.9%, v0.6.1, 768x512, 3.5 s")
    assert found == ["310.0 m", "1.44x", "2.7 h", "5.9%", "3.5 s"]


def test_the_shipped_policies_table_holds_their_cards_figures() -> None:
    """BENCHMARKS.md's table: a column per shipped policy, each cell its card's figure (the best
    constant's column the same on every card: the same episodes), and the card's command and
    wall time."""
    table = shipped_table(BENCHMARKS)
    header, rows = table_cells(table[0]), [table_cells(line) for line in table[2:]]
    by_scene = {row[0]: row for row in rows}
    shipped = shipped_policies()
    assert shipped, "no policy is shipped"
    assert header[2:] == [f"`pretrained:{name}`" for name in shipped]
    for column, folder in enumerate(shipped.values(), start=2):
        card = load_card(folder)
        assert card is not None, f"{folder} has no card"
        assert len(rows) == len(card["figures"]) + 1
        for index, figure in enumerate(card["figures"]):
            seeds = ", ".join(str(seed) for seed in figure["seeds"])
            label = "report" if index == 0 else "held out"
            row = by_scene[f"{label}: {figure['scene']} ({seeds}; {figure['episodes']})"]
            assert row[1] == (
                f"{figure['baseline_distance']:.1f} m, "
                f"{figure['baseline_collision_rate']:.2f} collided"
            )
            assert row[column] == (
                f"{figure['distance']:.1f} m, **{figure['ratio']:.2f}x**, "
                f"{figure['collision_rate']:.2f} collided"
            )
        retrain = f"`{card['command']}` ({hours(card['wall_seconds'])})"
        assert by_scene[RETRAIN_ROW][column] == retrain
