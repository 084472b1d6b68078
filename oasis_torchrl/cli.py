"""The ``oasis-torchrl`` console script: argparse with one sub-command per module of
:mod:`oasis_torchrl.commands`."""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
from collections.abc import Sequence
from types import ModuleType

from oasis_torchrl import __version__, commands

logger = logging.getLogger(__name__)

_COMMAND_ATTRIBUTES = ("NAME", "HELP", "add_arguments", "run")


def discover_commands() -> list[ModuleType]:
    """The command modules of :mod:`oasis_torchrl.commands`, sorted by module name.

    Example:
        >>> "serve" in [command.NAME for command in discover_commands()]
        True
    """
    found = []
    for module_info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{module_info.name}")
        missing = [name for name in _COMMAND_ATTRIBUTES if not hasattr(module, name)]
        if missing:
            raise TypeError(f"command module {module.__name__} lacks {', '.join(missing)}")
        found.append(module)
    return found


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser, one sub-parser per discovered command.

    Example:
        >>> build_parser().parse_args(["serve", "--port", "0"]).command
        'serve'
    """
    parser = argparse.ArgumentParser(
        prog="oasis-torchrl",
        description="Oasis world model tools: embedded A2V server, training, data, viewing.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument(
        "--log-level",
        default="INFO",
        choices=("DEBUG", "INFO", "WARNING", "ERROR"),
        help="logging threshold (default INFO)",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in discover_commands():
        subparser = subparsers.add_parser(command.NAME, help=command.HELP, description=command.HELP)
        command.add_arguments(subparser)
        subparser.set_defaults(run=command.run)
    return parser


def parse_arguments(
    parser: argparse.ArgumentParser, argv: Sequence[str] | None = None
) -> argparse.Namespace:
    """``parser.parse_args``, but ``KEY=VALUE`` overrides may also follow the options.

    Why: argparse fills a ``nargs="*"`` positional once, at its first position, so in
    ``train ppo --config c.yaml optim.lr=1e-4`` the override after the option is rejected;
    subcommands rule out ``parse_intermixed_args``.

    Example:
        >>> args = parse_arguments(build_parser(), ["train", "ppo", "--config", "c.yaml", "a=1"])
        >>> str(args.config), args.overrides
        ('c.yaml', ['a=1'])
    """
    args, extra = parser.parse_known_args(argv)
    overrides = [item for item in extra if "=" in item and not item.startswith("-")]
    if overrides and hasattr(args, "overrides"):
        args.overrides = [*args.overrides, *overrides]
        extra = [item for item in extra if item not in overrides]
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default: the process arguments), set up logging, run the command.

    Example:
        >>> main(["serve", "--width", "7"])  # invalid settings give exit code 2
        2
    """
    args = parse_arguments(build_parser(), argv)
    logging.basicConfig(
        level=args.log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    return int(args.run(args))
