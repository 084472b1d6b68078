"""Config fields with help text and command-line spelling: :func:`option`.

Every setting of every command is a field of a config dataclass; the field carries its help
text and, where the command line spells it differently from its dotted key, the flags that set
it. The YAML presets, ``key=value`` overrides and the generated ``--help`` all read these
dataclasses (:mod:`oasis_torchrl.config.loading`, :mod:`oasis_torchrl.config.arguments`).

A leaf module (the standard library only): the embedded server's settings
(:mod:`oasis_torchrl.sim.config`) use it too, and :mod:`oasis_torchrl.config` builds on them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import MISSING, dataclass
from typing import Any, get_type_hints

HELP = "help"
CLI = "cli"
REQUIRED = "???"
"""The default of a setting that must be given (OmegaConf's own marker of a missing value)."""


ALIASES = "ALIASES"
"""Name of a schema's optional class attribute mapping extra flags to settings, e.g.
``ALIASES: ClassVar = {"--num-envs": Alias("env.num_envs")}``: short spellings of nested
settings for the command line."""


@dataclass(frozen=True)
class CommandLine:
    """How a field's flag reads its value (every field gets ``--dotted-key``).

    Attributes:
        parse: turns the flag's text into the value (default: YAML, typed by the config).
        positional: the field is a positional argument instead of a flag.
        metavar: the value's name in ``--help``.
    """

    parse: Callable[[str], Any] | None = None
    positional: bool = False
    metavar: str | None = None


@dataclass(frozen=True)
class Alias:
    """Another flag for a setting (see :data:`ALIASES`).

    Attributes:
        key: the dotted key it sets.
        repeat: the flag may be given several times; the values form the setting's list.
    """

    key: str
    repeat: bool = False


def option(
    default: Any = MISSING,
    *,
    help: str,
    default_factory: Callable[[], Any] | Any = MISSING,
    parse: Callable[[str], Any] | None = None,
    positional: bool = False,
    metavar: str | None = None,
) -> Any:
    """A dataclass field with help text and its command-line spelling.

    Example:
        >>> from dataclasses import dataclass, fields
        >>> @dataclass
        ... class Example:
        ...     episodes: int = option(10, help="episodes to record", metavar="N")
        >>> field = fields(Example)[0]
        >>> field.default, field.metadata["help"], field.metadata["cli"].metavar
        (10, 'episodes to record', 'N')
    """
    metadata = {
        HELP: help,
        CLI: CommandLine(parse, positional, metavar),
    }
    return dataclasses.field(default=default, default_factory=default_factory, metadata=metadata)


@dataclass(frozen=True)
class Leaf:
    """One setting of a config tree: its dotted key, type, default, help and spelling."""

    key: str
    type: Any
    default: Any
    help: str
    cli: CommandLine

    @property
    def required(self) -> bool:
        """Whether the setting has no default (it must be given)."""
        return self.default == REQUIRED


@dataclass(frozen=True)
class Section:
    """A nested config dataclass: its dotted key and the first line of its docstring."""

    key: str
    title: str


def is_config(value: Any) -> bool:
    """Whether ``value`` is a config dataclass (a class, not an instance).

    Example:
        >>> is_config(CommandLine), is_config(int)
        (True, False)
    """
    return isinstance(value, type) and dataclasses.is_dataclass(value)


def walk(schema: type, prefix: str = "") -> Iterator[Leaf | Section]:
    """Every section and setting of ``schema``, depth first, in field order.

    Example:
        >>> from oasis_torchrl.config.env import EnvConfig
        >>> [item.key for item in walk(EnvConfig)][6:10]
        ['server', 'server.width', 'server.height', 'server.fps']
    """
    hints = get_type_hints(schema)
    for field in dataclasses.fields(schema):
        key = f"{prefix}{field.name}"
        kind = hints[field.name]
        if is_config(kind):
            yield Section(key, field.metadata.get(HELP) or _first_line(kind.__doc__))
            yield from walk(kind, f"{key}.")
            continue
        default = field.default
        if default is MISSING and field.default_factory is not MISSING:
            default = field.default_factory()
        yield Leaf(
            key,
            kind,
            default,
            field.metadata.get(HELP, ""),
            field.metadata.get(CLI, CommandLine()),
        )


def _first_line(text: str | None) -> str:
    return (text or "").strip().splitlines()[0] if text and text.strip() else ""
