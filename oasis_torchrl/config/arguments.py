"""Command-line arguments generated from a config dataclass.

Every setting gets one flag (``--env.max-steps``: the dotted key with hyphens, or the alias its
schema declares instead, e.g. ``--num-envs``) and can also be given as ``key=value`` anywhere
after the command; ``--config NAME`` (a preset) or ``--config FILE.yaml`` loads settings first.
Flags are applied after the file, ``key=value`` overrides last, so the same setting is never set
two ways by two systems: both are the config's own keys. ``--help`` lists every setting with its
help and default (or "required").
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.config.loading import load_config
from oasis_torchrl.config.presets import preset_names
from oasis_torchrl.options import ALIASES, Alias, Leaf, Section, walk

_DEST = "setting:"
"""Prefix of the argparse destinations that hold settings (keys may contain dots)."""
_ALIAS = "alias:"
"""Prefix of the destinations of alias flags (followed by the flag)."""
OVERRIDES = "overrides"


def add_config_arguments(parser: argparse.ArgumentParser, schema: type) -> None:
    """Add ``--config``, one argument per setting of ``schema``, and the overrides' help.

    Example:
        >>> from oasis_torchrl.config.env import EnvConfig
        >>> parser = argparse.ArgumentParser()
        >>> add_config_arguments(parser, EnvConfig)
        >>> args = parser.parse_args(["--num-envs", "4", "--server.width", "128"])
        >>> load_from_args(args, EnvConfig).server.width
        128
    """
    parser.add_argument(
        "--config",
        type=Path,
        metavar="NAME|FILE.yaml",
        help="a named preset (" + ", ".join(preset_names()) + ") or a YAML file of settings, "
        "applied before the flags and KEY=VALUE overrides",
    )
    leaves = {item.key: item for item in walk(schema) if isinstance(item, Leaf)}
    aliases = getattr(schema, ALIASES, {})
    for flag, alias in aliases.items():
        _add_alias(parser, flag, alias, leaves[alias.key])
    aliased = {alias.key for alias in aliases.values()}  # their alias is their one flag
    group: Any = parser
    for item in walk(schema):
        if isinstance(item, Section):
            group = parser.add_argument_group(item.key, item.title or None)
        elif item.key not in aliased:
            _add_leaf(group, item)
    parser.set_defaults(**{OVERRIDES: []})
    parser.epilog = (
        "Any setting can also be given as KEY=VALUE (dotted keys, YAML values), e.g. "
        + " ".join(_examples(schema))
    )


def _help(leaf: Leaf) -> str:
    default = "required" if leaf.required else f"default: {_shown(leaf.default)}"
    return f"{leaf.help} ({default})".replace("%", "%%")  # argparse formats help with %


def _add_leaf(group: Any, leaf: Leaf) -> None:
    if leaf.cli.positional:
        nargs = None if leaf.required else "?"
        metavar = leaf.cli.metavar or leaf.key.upper()
        group.add_argument(
            _DEST + leaf.key,
            metavar=metavar,
            nargs=nargs,
            help=_help(leaf),
            default=argparse.SUPPRESS,
        )
        return
    flag = "--" + leaf.key.replace("_", "-")
    group.add_argument(flag, help=_help(leaf), **_options(leaf, _DEST + leaf.key))


def _add_alias(parser: argparse.ArgumentParser, flag: str, alias: Alias, leaf: Leaf) -> None:
    options = _options(leaf, _ALIAS + flag)
    if alias.repeat:
        options["action"] = "append"
    parser.add_argument(flag, help=f"sets {leaf.key}: {_help(leaf)}", **options)


def _options(leaf: Leaf, dest: str) -> dict[str, Any]:
    options: dict[str, Any] = {"dest": dest, "default": argparse.SUPPRESS}
    if leaf.type is bool:
        options["action"] = argparse.BooleanOptionalAction
    else:
        options["metavar"] = leaf.cli.metavar or leaf.key.rsplit(".", 1)[-1].upper()
    return options


def _shown(default: Any) -> str:
    if isinstance(default, (list, tuple)):
        return "[" + ", ".join(str(value) for value in default) + "]"
    return "null" if default is None else str(default)


def _examples(schema: type) -> list[str]:
    leaves = [item for item in walk(schema) if isinstance(item, Leaf) and "." in item.key]
    return [f"{leaf.key}={_shown(leaf.default)}" for leaf in leaves[:2]]


def split_overrides(extra: Sequence[str]) -> tuple[list[str], list[str]]:
    """Split what argparse left over into ``key=value`` overrides and the rest.

    Example:
        >>> split_overrides(["optim.lr=1e-4", "--nope"])
        (['optim.lr=1e-4'], ['--nope'])
    """
    overrides = [item for item in extra if "=" in item and not item.startswith("-")]
    return overrides, [item for item in extra if item not in overrides]


def load_from_args(args: argparse.Namespace, schema: type) -> DictConfig:
    """The config the parsed arguments describe (file, then flags, then overrides).

    Raises:
        ValueError: an unknown key or a bad value, named (see
            :func:`~oasis_torchrl.config.loading.load_config`).
    """
    overrides = getattr(args, OVERRIDES, [])
    return load_config(schema, overrides, file=args.config, values=flag_values(args, schema))


def flag_values(args: argparse.Namespace, schema: type) -> list[tuple[str, Any]]:
    """The ``(key, value)`` pairs of the settings the parsed flags set, in the order given.

    Example:
        >>> from oasis_torchrl.config.env import EnvConfig
        >>> parser = argparse.ArgumentParser()
        >>> add_config_arguments(parser, EnvConfig)
        >>> flag_values(parser.parse_args(["--num-envs", "4"]), EnvConfig)
        [('num_envs', 4)]
    """
    leaves = {item.key: item for item in walk(schema) if isinstance(item, Leaf)}
    aliases = getattr(schema, ALIASES, {})
    values = []
    for dest, raw in vars(args).items():
        if dest.startswith(_ALIAS):
            key = aliases[dest.removeprefix(_ALIAS)].key
            values.append((key, _value(leaves[key], raw)))
        elif dest.startswith(_DEST):
            key = dest.removeprefix(_DEST)
            values.append((key, _value(leaves[key], raw)))
    return values


def _value(leaf: Leaf, raw: Any) -> Any:
    """A flag's text as the setting's value: its own parser, else a YAML value (numbers,
    lists, null) that the config then checks against the type; plain text for strings. A list
    setting also takes its items without the brackets (``--pool-grid 8,12``). A repeated alias
    gives a list of such values."""
    if isinstance(raw, bool):
        return raw
    if isinstance(raw, list):
        return [_value(leaf, item) for item in raw]
    if leaf.cli.parse is not None:
        return leaf.cli.parse(raw)
    if leaf.type is str or _is_text_list(leaf.type):
        return raw
    if _is_list(leaf.type) and not raw.strip().startswith(("[", "null")):
        raw = f"[{raw}]"
    return OmegaConf.from_dotlist([f"value={raw}"]).value


def _is_list(kind: Any) -> bool:
    return getattr(kind, "__origin__", None) in (list, tuple)


def _is_text_list(kind: Any) -> bool:
    """``list[str]`` or ``tuple[str, ...]``: each flag value is one item, as typed."""
    items = getattr(kind, "__args__", ())
    return bool(items) and items[0] is str and all(item in (str, Ellipsis) for item in items)
