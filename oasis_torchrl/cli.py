"""The ``oasis-torchrl`` console script: one sub-command per module of
:mod:`oasis_torchrl.commands`, its arguments generated from the command's config dataclass."""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
from collections.abc import Sequence
from types import ModuleType

from oasis_torchrl import __version__, commands
from oasis_torchrl.allocator import keep_batches_in_heap
from oasis_torchrl.config.arguments import (
    OVERRIDES,
    add_config_arguments,
    load_from_args,
    split_overrides,
)

logger = logging.getLogger(__name__)

_COMMAND_ATTRIBUTES = ("NAME", "HELP", "CONFIG", "run")


def discover_commands() -> list[ModuleType]:
    """The command modules of :mod:`oasis_torchrl.commands`, sorted by module name.

    Example:
        >>> "serve" in [command.NAME for command in discover_commands()]
        True
    """
    modules = []
    for module_info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if module_info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{module_info.name}")
        missing = [name for name in _COMMAND_ATTRIBUTES if not hasattr(module, name)]
        if missing:
            raise TypeError(f"command module {module.__name__} lacks {', '.join(missing)}")
        modules.append(module)
    return modules


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser: one sub-parser per command (per algorithm for ``train``).

    Example:
        >>> build_parser().parse_args(["serve", "--port", "0"]).command.NAME
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
    subparsers = parser.add_subparsers(dest="command_name", required=True, metavar="COMMAND")
    for command in discover_commands():
        subparser = subparsers.add_parser(command.NAME, help=command.HELP, description=command.HELP)
        subparser.set_defaults(command=command)
        if isinstance(command.CONFIG, dict):
            choices = subparser.add_subparsers(dest="choice", required=True, metavar="CHOICE")
            for name, schema in command.CONFIG.items():
                described = (schema.__doc__ or "").strip()
                choice = choices.add_parser(name, help=described.splitlines()[0])
                choice.description = described
                add_config_arguments(choice, schema)
                choice.set_defaults(schema=schema)
        else:
            add_config_arguments(subparser, command.CONFIG)
            subparser.set_defaults(schema=command.CONFIG, choice=None)
    return parser


def parse_arguments(
    parser: argparse.ArgumentParser, argv: Sequence[str] | None = None
) -> argparse.Namespace:
    """``parser.parse_args``, but ``KEY=VALUE`` overrides may stand anywhere after the command.

    Example:
        >>> args = parse_arguments(build_parser(), ["train", "ppo", "optim.lr=1e-4", "--seed", "3"])
        >>> args.overrides, args.choice
        (['optim.lr=1e-4'], 'ppo')
    """
    args, extra = parser.parse_known_args(argv)
    overrides, unknown = split_overrides(extra)
    if unknown:
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    setattr(args, OVERRIDES, overrides)
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default: the process arguments), set up logging, run the command.

    Exit codes: 0 done, 2 bad settings (named in the log), others as the command says.

    Example:
        >>> main(["eval", "episodes=-1"])
        2
    """
    args = parse_arguments(build_parser(), argv)
    logging.basicConfig(format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    # The level is set apart: basicConfig does nothing once the root logger has a handler, and
    # a library can give it one at import (LeRobot's import checks log before anything else).
    logging.getLogger().setLevel(args.log_level)
    keep_batches_in_heap()
    command = args.command
    try:
        cfg = load_from_args(args, args.schema)
    except (ValueError, FileNotFoundError) as error:
        logger.error("%s: bad settings: %s", command.NAME, error)
        return 2
    return int(command.run(cfg) if args.choice is None else command.run(cfg, args.choice))
