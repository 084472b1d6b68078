"""Every shell command of the README and the docs' pages that can run offline is checked
without running it, so a renamed flag, setting, preset or make target fails the suite:
``oasis-torchrl`` lines are parsed by the command's own parser and their config loaded,
LeRobot's tools' flags are looked up in their config dataclasses, a script's flags are parsed
by the script's parser, ``make`` targets are looked up in the Makefile. Commands that are not
the project's (``pip``, ``git``, ``ssh``, ...) are listed, each with why it is not checked."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import pytest

from ._commands import (
    ARGPARSE_TOOLS,
    LEROBOT_TOOLS,
    Command,
    check_argparse_tool,
    check_lerobot_flags,
    check_make,
    check_oasis_torchrl,
    check_script,
    lerobot_config,
    page_commands,
)
from ._hooks import ROOT

PAGES = [
    ROOT / "README.md",
    *sorted((ROOT / "docs").glob("*.md")),
    *sorted((ROOT / "docs" / "guides").glob("*.md")),
]
NOT_CHECKED = {
    "pip": "installs packages (the network)",
    "git": "changes the repository",
    "ssh": "another machine",
    "export": "sets a variable for the lines after it",
    "rerun": "the rerun viewer, another project's command",
    "python -c": "a Python statement on the user's data",
}
"""Programs whose lines are not checked, and why."""


def program(command: Command) -> str:
    """The name a line is checked by: the program, ``python -m MODULE``, ``python SCRIPT``."""
    words = command.words
    if words[0] in ("python", "python3") and len(words) > 1:
        return f"python {words[1]}" if words[1] != "-m" else f"python -m {words[2]}"
    return words[0]


COMMANDS = [command for page in PAGES for command in page_commands(page)]


def test_the_pages_have_commands_of_each_kind() -> None:
    kinds = {program(command) for command in COMMANDS}
    assert {"oasis-torchrl", "make", "lerobot-train", "lerobot-eval"} <= kinds


def check(command: Command) -> None:
    """Check one line as its program says, or fail naming a program nobody decided on."""
    words, name = list(command.words), program(command)
    if name in ("oasis-torchrl", "python -m oasis_torchrl"):
        argv = words[1:] if name == "oasis-torchrl" else words[3:]
        with contextlib.redirect_stdout(io.StringIO()):  # --help prints
            check_oasis_torchrl(argv)
    elif name in LEROBOT_TOOLS or name.removeprefix("python -m ") in LEROBOT_TOOLS:
        tool = name.removeprefix("python -m ")
        check_lerobot_flags(lerobot_config(tool), words[3 if name != tool else 1 :])
    elif name in ARGPARSE_TOOLS:
        check_argparse_tool(name, words[1:])
    elif name.startswith("python ") and name.endswith(".py"):
        check_script(words[1], words[2:])
    elif name == "make":
        check_make(words[1:])
    else:
        assert name in NOT_CHECKED, f"{command}: {name} is neither checked nor in NOT_CHECKED"


@pytest.mark.parametrize("command", COMMANDS, ids=str)
def test_each_command_parses(
    command: Command, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    if "lerobot" in program(command):
        pytest.importorskip("lerobot", reason="the lerobot extra is not installed")
    monkeypatch.chdir(tmp_path)  # LeRobot's async modules open log files in logs/ at import
    check(command)


@pytest.mark.parametrize(
    "line",
    [
        "oasis-torchrl train ppo --env.num_envs 16",  # the flag is --env.num-envs
        "oasis-torchrl eval policy=x episodez=16",
        "oasis-torchrl eval --config hostd",
        "make benchmarks",
        "python benchmarks/learning.py --stagez bc",
    ],
)
def test_a_renamed_flag_fails(line: str, tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(f"```bash\n{line}\n```\n")
    (command,) = page_commands(page)
    with pytest.raises((AssertionError, ValueError, FileNotFoundError)):
        check(command)


def test_a_lerobot_flag_not_in_its_config_fails() -> None:
    pytest.importorskip("lerobot", reason="the lerobot extra is not installed")
    config = lerobot_config("lerobot-eval")
    check_lerobot_flags(config, ["--env.type=oasis", "--env.front_crop=0.25", "--policy.path=p"])
    with pytest.raises(AssertionError, match="front_crop"):
        check_lerobot_flags(config, ["--policy.path=p", "--env.front_crop=0.25"])
    with pytest.raises(AssertionError, match="batchsize"):
        check_lerobot_flags(config, ["--eval.batchsize=8"])
