"""The shell commands of the README and the docs' pages, and checks of their flags that run
nothing: ``oasis-torchrl`` lines through the command's own parser and config loading, LeRobot's
tools against their config dataclasses (or their argparse parser), a script through its
``parse_arguments``, ``make`` targets against the Makefile."""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib
import importlib.util
import inspect
import re
import shlex
import sys
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from unittest import mock

from ._hooks import ROOT

SHELL_BLOCK = re.compile(r"^```(?:bash|sh|shell)\n(?P<code>.*?)^```", re.DOTALL | re.MULTILINE)
FENCE = re.compile(r"^```.*?^```", re.DOTALL | re.MULTILINE)
INLINE = re.compile(r"`(?P<code>(?:oasis-torchrl|lerobot-[\w-]+|make) [^`]*(?: -|=)[^`]*)`")
"""A command in running text: one of the project's, LeRobot's or make's, with a flag or a
setting (a bare name such as ``oasis-torchrl eval`` names the command, it is no command line)."""
PLACEHOLDER = re.compile(r"<|\.\.\.|=$|=\s|\bPATH\b")
SUBSTITUTION = re.compile(r"\$\([^()]*\)")
OPERATORS = {"&&", "||", ";", "|", "&"}
ASSIGNMENT = re.compile(r"^[A-Za-z_]\w*=")
SUBSTITUTED = "/tmp/substituted"
"""What a ``$(...)`` stands for: its output is a path wherever the pages use one."""


@dataclass(frozen=True)
class Command:
    """One simple command of a page's shell block: its words, without variable assignments."""

    page: str
    words: tuple[str, ...]

    def __str__(self) -> str:
        return f"{self.page}: {shlex.join(self.words)}"


def page_commands(page: Path) -> list[Command]:
    """The simple commands of ``page``'s shell blocks and of its running text (:data:`INLINE`,
    placeholders such as ``PATH`` or ``<command>`` left out): continued lines joined, comments
    and ``VAR=value`` prefixes dropped, ``$(...)`` replaced by a path.

    Example:
        >>> import tempfile
        >>> page = Path(tempfile.mkdtemp()) / "p.md"
        >>> block = "A=1 cmd --x \\\\\\n  y  # note\\nexport B=2 && b $(c)\\n"
        >>> _ = page.write_text(f"```bash\\n{block}```\\n")
        >>> [c.words for c in page_commands(page)]
        [('cmd', '--x', 'y'), ('export', 'B=2'), ('b', '/tmp/substituted')]
    """
    text = page.read_text()
    lines = [block["code"].replace("\\\n", " ") for block in SHELL_BLOCK.finditer(text)]
    lines += [
        span["code"].replace("\n", " ")
        for span in INLINE.finditer(FENCE.sub("", text))
        if not PLACEHOLDER.search(span["code"])
    ]
    commands = []
    for code in lines:
        for line in SUBSTITUTION.sub(SUBSTITUTED, code).splitlines():
            commands += [Command(page.name, words) for words in _split(line)]
    return commands


def _split(line: str) -> list[tuple[str, ...]]:
    lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    simple: list[list[str]] = [[]]
    for token in lexer:
        if token in OPERATORS:
            simple.append([])
        else:
            simple[-1].append(token)
    found = []
    for words in simple:
        while words and ASSIGNMENT.match(words[0]):  # VAR=value before a command, or alone
            words = words[1:]
        if words:
            found.append(tuple(words))
    return found


def makefile_targets(makefile: Path = ROOT / "Makefile") -> set[str]:
    """The targets the Makefile defines.

    Example:
        >>> {"demo", "test", "bench"} <= makefile_targets()
        True
    """
    return set(re.findall(r"^([\w-]+):(?!=)", makefile.read_text(), re.MULTILINE))


def check_make(argv: list[str]) -> None:
    """Every target of a ``make`` line (``VAR=value`` words aside) is the Makefile's."""
    unknown = {word for word in argv if "=" not in word} - makefile_targets()
    assert not unknown, f"the Makefile has no target {sorted(unknown)}"


def check_script(path: str, argv: list[str]) -> None:
    """Parse ``argv`` with the script's ``parse_arguments`` and load the config it describes
    (``benchmark_config``) where it has one: the script is imported, not run."""
    script = ROOT / path
    spec = importlib.util.spec_from_file_location(f"docs_script_{script.stem}", script)
    assert spec is not None and spec.loader is not None, path
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # a dataclass of the script looks its module up there
    sys.path.insert(0, str(script.parent))  # as `python <script>` does: its helpers import
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(script.parent))
    assert hasattr(module, "parse_arguments"), f"{path} has no parse_arguments(argv) to check"
    try:
        parsed = module.parse_arguments(argv)
    except SystemExit as exit_:
        raise AssertionError(f"{path} refused it (exit {exit_.code})") from None
    if hasattr(module, "benchmark_config"):
        module.benchmark_config(*parsed)


def check_oasis_torchrl(argv: list[str]) -> None:
    """Parse ``argv`` as ``oasis-torchrl`` does and load its config, running nothing; a help
    or version flag must exit 0."""
    from oasis_torchrl.cli import build_parser, parse_arguments
    from oasis_torchrl.config.arguments import load_from_args

    try:
        args = parse_arguments(build_parser(), argv)
    except SystemExit as exit_:
        if exit_.code not in (0, None):
            raise AssertionError(f"the parser refused it (exit {exit_.code})") from None
        return
    load_from_args(args, args.schema)


LEROBOT_TOOLS = {
    "lerobot-train": ("lerobot.scripts.lerobot_train", "train"),
    "lerobot-eval": ("lerobot.scripts.lerobot_eval", "eval_main"),
    "lerobot-record": ("lerobot.scripts.lerobot_record", "record"),
    "lerobot-replay": ("lerobot.scripts.lerobot_replay", "replay"),
    "lerobot-rollout": ("lerobot.scripts.lerobot_rollout", "rollout"),
    "lerobot-teleoperate": ("lerobot.scripts.lerobot_teleoperate", "teleoperate"),
    "lerobot.async_inference.policy_server": ("lerobot.async_inference.policy_server", "serve"),
    "lerobot.async_inference.robot_client": (
        "lerobot.async_inference.robot_client",
        "async_client",
    ),
}
"""A LeRobot tool (a console script or a ``python -m`` module) -> its entry function, whose
first parameter's annotation is the config dataclass its flags set."""

ARGPARSE_TOOLS = {"lerobot-dataset-viz": ("lerobot.scripts.lerobot_dataset_viz", "main")}
"""A LeRobot tool whose ``main`` parses its flags with argparse -> that ``main``."""

PATH_FLAGS = {"policy.path", "config_path"}
"""Flags LeRobot's parser takes before draccus sees the rest."""


@functools.cache
def lerobot_config(tool: str) -> type:
    """The config dataclass of a LeRobot tool (imports the tool's module and the plugins, as
    the tool does before parsing; runs nothing)."""
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    module_name, function = LEROBOT_TOOLS[tool]
    entry = inspect.unwrap(getattr(importlib.import_module(module_name), function))
    annotation = next(iter(inspect.signature(entry).parameters.values())).annotation
    return entry.__globals__[annotation] if isinstance(annotation, str) else annotation


class _Parsed(Exception):
    """Raised where a ``main`` has parsed its arguments, to stop it before it runs."""


def check_argparse_tool(tool: str, argv: list[str]) -> None:
    """Run an argparse tool's ``main`` up to its ``parse_args`` on ``argv``, then stop it."""
    module_name, function = ARGPARSE_TOOLS[tool]
    main = getattr(importlib.import_module(module_name), function)
    parse_args = argparse.ArgumentParser.parse_args

    def parse_then_stop(parser: argparse.ArgumentParser, *_: Any, **__: Any) -> None:
        parse_args(parser, argv)
        raise _Parsed

    with mock.patch.object(argparse.ArgumentParser, "parse_args", parse_then_stop):
        try:
            main()
        except _Parsed:
            return
        except SystemExit as exit_:
            raise AssertionError(f"{tool} refused it (exit {exit_.code})") from None
    raise AssertionError(f"{tool}'s main never parsed its arguments")


def check_lerobot_flags(config: type, argv: list[str]) -> None:
    """Every ``--a.b=value`` of ``argv`` names a field of ``config`` (choice types followed
    through the ``--a.type=name`` given), as draccus would parse it."""
    flags = [word[2:].split("=", 1) for word in argv if word.startswith("--")]
    chosen = {key[: -len(".type")]: value for key, *value in flags if key.endswith(".type")}
    chosen = {key: value[0] for key, value in chosen.items() if value}
    for key, *_ in flags:
        if key in PATH_FLAGS:
            continue
        _field_path(config, key.split("."), chosen)


def _field_path(config: type, parts: list[str], chosen: dict[str, str]) -> None:
    node: Any = config
    for depth, part in enumerate(parts):
        prefix = ".".join(parts[:depth])
        if part == "type" and prefix in chosen:
            return
        names = {field.name for field in dataclasses.fields(node)}
        if part not in names:
            raise AssertionError(f"--{'.'.join(parts)}: {node.__name__} has no field {part!r}")
        hint = _strip_optional(typing.get_type_hints(node)[part])
        if depth == len(parts) - 1:
            return
        path = ".".join(parts[: depth + 1])
        if path in chosen and hasattr(hint, "get_choice_class"):
            hint = hint.get_choice_class(chosen[path])
        if not dataclasses.is_dataclass(hint):
            raise AssertionError(f"--{'.'.join(parts)}: {path} is not a section")
        node = hint


def _strip_optional(hint: Any) -> Any:
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        args = [arg for arg in typing.get_args(hint) if arg is not type(None)]
        return args[0] if len(args) == 1 else hint
    return hint
