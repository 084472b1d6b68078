"""Config fields with help text, command-line spelling and bounds: :func:`option`.

Every setting of every command is a field of a config dataclass; the field carries its help
text, the values it accepts (:class:`Bounds`) and, where the command line spells it differently
from its dotted key, the flags that set it. The YAML presets, ``key=value`` overrides and the
generated ``--help`` all read these dataclasses (:mod:`oasis_torchrl.config.loading`,
:mod:`oasis_torchrl.config.arguments`), and :func:`check_bounds` checks every declared bound of a
config tree in one pass.

A leaf module (the standard library only): the embedded server's settings
(:mod:`oasis_torchrl.sim.config`) use it too, and :mod:`oasis_torchrl.config` builds on them.
"""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Callable, Iterator
from dataclasses import MISSING, dataclass
from typing import Any, Union, get_args, get_origin, get_type_hints

HELP = "help"
CLI = "cli"
BOUNDS = "bounds"
REQUIRED = "???"
"""The default of a setting that must be given (OmegaConf's own marker of a missing value)."""


ALIASES = "ALIASES"
"""Name of a schema's optional class attribute mapping extra flags to settings, e.g.
``ALIASES: ClassVar = {"--num-envs": Alias("env.num_envs")}``: short spellings of nested
settings for the command line."""


RENAMED = "RENAMED"
"""Name of a config section's optional class attribute mapping the dotted keys of settings that
moved to their keys now, e.g. ``RENAMED: ClassVar = {"policy.optimizer_lr": "optim.lr"}``:
configs saved before the move still load (:func:`renamed_keys`)."""


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


def is_integer(value: object) -> bool:
    """Whether ``value`` is an integer (``True`` and ``False`` are not).

    Example:
        >>> is_integer(3), is_integer(3.0), is_integer(True)
        (True, False, False)
    """
    return isinstance(value, int) and not isinstance(value, bool)


def is_number(value: object) -> bool:
    """Whether ``value`` is an integer or a float other than NaN.

    Example:
        >>> is_number(0.5), is_number(float("nan")), is_number("1")
        (True, False, False)
    """
    return is_integer(value) or (isinstance(value, float) and not math.isnan(value))


@dataclass(frozen=True)
class Bounds:
    """The values a setting accepts: a number within ``ge``/``gt`` (at least / above) and
    ``le``/``lt`` (at most / below), or one of ``choices``. ``ge`` and ``le`` are inclusive,
    ``gt`` and ``lt`` exclusive: ``gt=0`` is strictly positive. A null value always passes:
    whether a setting may be null is its type's concern.

    Example:
        >>> Bounds(ge=0, le=8).check("vp9_cpu_used", 9, int)
        Traceback (most recent call last):
        ...
        ValueError: vp9_cpu_used must be an integer in [0, 8], got 9
        >>> Bounds(gt=0).check("optim.anneal_frames", 0, int | None)
        Traceback (most recent call last):
        ...
        ValueError: optim.anneal_frames must be an integer > 0 or null, got 0
        >>> Bounds(choices=("csv", "tensorboard")).check("logger.backend", "csv", str)
    """

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    choices: tuple[Any, ...] | None = None

    def check(self, key: str, value: Any, kind: Any) -> None:
        """Raise a one-line ``ValueError`` naming ``key`` and ``value`` if ``value`` is out of
        bounds (``kind``: the setting's type, which says integer or number, and null or not)."""
        if value is None or self._admits(value, _nullable(kind)[0]):
            return
        raise ValueError(f"{key} must be {self.describe(kind)}, got {value!r}")

    def describe(self, kind: Any) -> str:
        """What the setting must be, e.g. ``an integer in [0, 8]`` or ``a number > 0 or null``.

        Example:
            >>> Bounds(ge=0.0, lt=1.0).describe(float)
            'a number in [0.0, 1.0)'
        """
        base, nullable = _nullable(kind)
        if self.choices is not None:
            what = f"one of {self.choices}"
        else:
            what = f"{'an integer' if base is int else 'a number'} {self._range()}"
        return f"{what} or null" if nullable else what

    def _admits(self, value: Any, base: Any) -> bool:
        if self.choices is not None:
            return value in self.choices
        if not (is_integer(value) if base is int else is_number(value)):
            return False
        return (
            (self.ge is None or value >= self.ge)
            and (self.gt is None or value > self.gt)
            and (self.le is None or value <= self.le)
            and (self.lt is None or value < self.lt)
        )

    def _range(self) -> str:
        low, low_open = (self.gt, True) if self.gt is not None else (self.ge, False)
        high, high_open = (self.lt, True) if self.lt is not None else (self.le, False)
        if low is not None and high is not None:
            return f"in {'(' if low_open else '['}{low}, {high}{')' if high_open else ']'}"
        if low is not None:
            return f"{'>' if low_open else '>='} {low}"
        return f"{'<' if high_open else '<='} {high}"


def _nullable(kind: Any) -> tuple[Any, bool]:
    """``(int, True)`` for ``int | None``; ``(int, False)`` for ``int``."""
    if get_origin(kind) not in (Union, types.UnionType):
        return kind, False
    others = [arg for arg in get_args(kind) if arg is not type(None)]
    return others[0], type(None) in get_args(kind)


def option(
    default: Any = MISSING,
    *,
    help: str,
    default_factory: Callable[[], Any] | Any = MISSING,
    parse: Callable[[str], Any] | None = None,
    positional: bool = False,
    metavar: str | None = None,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    choices: tuple[Any, ...] | None = None,
) -> Any:
    """A dataclass field with help text, its command-line spelling and its bounds.

    ``ge``, ``gt``, ``le``, ``lt`` and ``choices`` declare the values it accepts
    (:class:`Bounds`); the config loader checks them, and a dataclass built outside it calls
    :func:`check_bounds` itself.

    Example:
        >>> from dataclasses import dataclass, fields
        >>> @dataclass
        ... class Example:
        ...     episodes: int = option(10, help="episodes to record", metavar="N", ge=1)
        >>> field = fields(Example)[0]
        >>> field.default, field.metadata["help"], field.metadata["cli"].metavar
        (10, 'episodes to record', 'N')
        >>> field.metadata["bounds"]
        Bounds(ge=1, gt=None, le=None, lt=None, choices=None)
    """
    metadata: dict[str, Any] = {HELP: help, CLI: CommandLine(parse, positional, metavar)}
    bounds = Bounds(ge, gt, le, lt, choices)
    if bounds != Bounds():
        metadata[BOUNDS] = bounds
    return dataclasses.field(default=default, default_factory=default_factory, metadata=metadata)


@dataclass(frozen=True)
class Leaf:
    """One setting of a config tree: its dotted key, type, default, help, spelling and
    bounds."""

    key: str
    type: Any
    default: Any
    help: str
    cli: CommandLine
    bounds: Bounds | None = None

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


def walk(schema: type, prefix: str = "", defaults: Any = None) -> Iterator[Leaf | Section]:
    """Every section and setting of ``schema``, depth first, in field order; a setting's default
    is its section's (``defaults``, the section's default value, where a section sets its own).

    Example:
        >>> from oasis_torchrl.config.env import EnvConfig
        >>> [item.key for item in walk(EnvConfig)][6:10]
        ['server', 'server.width', 'server.height', 'server.fps']
    """
    hints = get_type_hints(schema)
    for field in dataclasses.fields(schema):
        key = f"{prefix}{field.name}"
        kind = hints[field.name]
        default = _default(field) if defaults is None else getattr(defaults, field.name)
        if is_config(kind):
            yield Section(key, field.metadata.get(HELP) or _first_line(kind.__doc__))
            yield from walk(kind, f"{key}.", None if default is MISSING else default)
            continue
        yield Leaf(
            key,
            kind,
            default,
            field.metadata.get(HELP, ""),
            field.metadata.get(CLI, CommandLine()),
            field.metadata.get(BOUNDS),
        )


def _default(field: dataclasses.Field) -> Any:
    if field.default is MISSING and field.default_factory is not MISSING:
        return field.default_factory()
    return field.default


def renamed_keys(schema: type, prefix: str = "") -> dict[str, str]:
    """The dotted keys that configs saved before a rename spell otherwise, and their keys now:
    each section's ``RENAMED`` class attribute (:data:`RENAMED`), nested sections too.

    Example:
        >>> from oasis_torchrl.config.pipeline import DemoConfig
        >>> renamed_keys(DemoConfig)["bc.policy.optimizer_lr"]
        'bc.optim.lr'
    """
    hints = get_type_hints(schema)
    renamed = {
        f"{prefix}{old}": f"{prefix}{new}" for old, new in getattr(schema, RENAMED, {}).items()
    }
    for field in dataclasses.fields(schema):
        if is_config(hints[field.name]):
            renamed |= renamed_keys(hints[field.name], f"{prefix}{field.name}.")
    return renamed


def check_bounds(schema: type, value_of: Callable[[str], Any]) -> None:
    """Check every declared bound of ``schema``'s settings, nested sections too, against the
    values ``value_of`` gives by dotted key; the first one out of bounds raises.

    Raises:
        ValueError: ``<dotted key> must be <what>, got <value>``.

    Example:
        >>> from oasis_torchrl.config.env import EnvConfig
        >>> check_bounds(EnvConfig, {"num_envs": 0, "reward.kind": "auto"}.get)
        Traceback (most recent call last):
        ...
        ValueError: num_envs must be an integer >= 1, got 0
    """
    for item in walk(schema):
        if isinstance(item, Leaf) and item.bounds is not None:
            item.bounds.check(item.key, value_of(item.key), item.type)


def _first_line(text: str | None) -> str:
    return (text or "").strip().splitlines()[0] if text and text.strip() else ""
