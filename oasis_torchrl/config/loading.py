"""Loading a config: the schema's defaults, a YAML preset, then overrides (Hydra's structured
configs, as TorchRL's recipes use them).

A command's settings are a dataclass (the schema: types, defaults, help and bounds declared
with :func:`~oasis_torchrl.options.option`, rules between settings in ``__post_init__``).
:func:`load_config` builds an OmegaConf ``DictConfig`` from it, merges a YAML preset (a named
one, :mod:`oasis_torchrl.config.presets`, or any file), then values set by flags and
``key=value`` overrides (``optim.lr=1e-4``, ``env.prompts=[urban,rural]``). The result is in
struct mode and typed: a key the schema lacks, or a value of the wrong type, is an error naming
it; then every declared bound is checked once, naming the setting by its dotted key, and the
dataclasses' own rules run before the config is returned.
"""

from __future__ import annotations

import dataclasses
import difflib
import logging
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import ConfigAttributeError, ConfigKeyError, OmegaConfBaseException

from oasis_torchrl.config.presets import preset_file
from oasis_torchrl.options import check_bounds, renamed_keys

logger = logging.getLogger(__name__)


def _named() -> dict[str, type]:
    from oasis_torchrl.config.evaluation import EvalConfig
    from oasis_torchrl.config.pipeline import DemoConfig
    from oasis_torchrl.config.policy_serving import ServePolicyConfig
    from oasis_torchrl.config.recording import ImportConfig, RecordConfig
    from oasis_torchrl.config.serving import ServeConfig
    from oasis_torchrl.config.training import BCConfig, PPOConfig
    from oasis_torchrl.config.viewing import FilmConfig, ViewConfig
    from oasis_torchrl.config.web import PlayConfig

    return {
        "bc": BCConfig,
        "demo": DemoConfig,
        "eval": EvalConfig,
        "film": FilmConfig,
        "import-recordings": ImportConfig,
        "play": PlayConfig,
        "ppo": PPOConfig,
        "record": RecordConfig,
        "serve": ServeConfig,
        "serve-policy": ServePolicyConfig,
        "view": ViewConfig,
    }


def config_names() -> list[str]:
    """The configs :func:`load_config` knows by name.

    Example:
        >>> config_names()[:4]
        ['bc', 'demo', 'eval', 'film']
    """
    return sorted(_named())


def schema_of(config: str | type) -> type:
    """The dataclass of a named config (``"ppo"``), or ``config`` itself if it is one.

    Example:
        >>> schema_of("demo").__name__
        'DemoConfig'
    """
    if isinstance(config, type):
        return config
    named = _named()
    if config not in named:
        raise ValueError(f"no config named {config!r}; known: {', '.join(sorted(named))}")
    return named[config]


def load_config(
    config: str | type,
    overrides: Sequence[str] = (),
    *,
    file: str | Path | None = None,
    values: Iterable[tuple[str, Any]] = (),
) -> DictConfig:
    """The typed config of a command: defaults, then ``file``, ``values``, ``overrides``.

    Args:
        config: a config dataclass, or the name of one (:func:`config_names`).
        overrides: ``key=value`` strings (dotted keys, YAML values).
        file: a YAML file whose keys override the defaults, or a preset's name.
        values: ``(key, value)`` pairs already parsed (from command-line flags).

    Raises:
        ValueError: an unknown key, a value of the wrong type, a failed check, or an unknown
            preset, named.
        FileNotFoundError: ``file`` does not exist.

    Example:
        >>> cfg = load_config("ppo", ["optim.lr=0.001", "env.num_envs=2"])
        >>> cfg.optim.lr, cfg.env.num_envs
        (0.001, 2)
        >>> load_config("ppo", ["optim.learning_rate=1"])
        Traceback (most recent call last):
        ...
        ValueError: optim.learning_rate=1: unknown key 'optim.learning_rate'
        >>> load_config("ppo", ["env.num_envs=0"])
        Traceback (most recent call last):
        ...
        ValueError: env.num_envs must be an integer >= 1, got 0
    """
    schema = schema_of(config)
    renamed = renamed_keys(schema)
    cfg = OmegaConf.structured(schema)
    _make_writable(cfg)
    OmegaConf.set_struct(cfg, True)
    if file is not None:
        path = preset_file(file)
        if not path.is_file():
            raise FileNotFoundError(f"config file {str(path)!r} not found")
        cfg = _merged(cfg, _moved(OmegaConf.load(path), renamed), path.name)
    for key, value in values:
        cfg = _merged(cfg, None, f"--{key}", key, value)
    for override in overrides:
        if "=" not in override:
            raise ValueError(f"override {override!r} must look like key=value")
        cfg = _merged(cfg, _moved(OmegaConf.from_dotlist([override]), renamed), override)
    try:
        OmegaConf.resolve(cfg)
        check_bounds(schema, lambda key: OmegaConf.select(cfg, key))
        OmegaConf.to_object(cfg)  # runs the dataclasses' rules between settings
    except OmegaConfBaseException as error:
        raise ValueError(_describe(error)) from error
    return cfg


def _moved(update: DictConfig, renamed: dict[str, str]) -> DictConfig:
    """``update`` (settings read from a file or an override) with the settings it spells as
    before a rename (``renamed``: old dotted key -> key now) at their keys now.

    Example:
        >>> update = OmegaConf.create({"policy": {"optimizer_lr": 0.01, "loss": "nll"}})
        >>> OmegaConf.to_container(_moved(update, {"policy.optimizer_lr": "optim.lr"}))
        {'policy': {'loss': 'nll'}, 'optim': {'lr': 0.01}}
    """
    for old, new in renamed.items():
        parent, _, name = old.rpartition(".")
        holder = OmegaConf.select(update, parent) if parent else update
        if isinstance(holder, DictConfig) and name in holder:
            logger.info("%s is now %s; configs should spell it so", old, new)
            value = OmegaConf.to_container(holder)[name]  # an interpolation moves unresolved
            del holder[name]
            OmegaConf.update(update, new, value, merge=False)
    return update


def _merged(
    cfg: DictConfig,
    update: DictConfig | None,
    source: str,
    key: str | None = None,
    value: Any = None,
) -> DictConfig:
    """``cfg`` with ``update`` merged (or ``key`` set to ``value``), errors naming ``source``."""
    try:
        if key is None:
            return OmegaConf.merge(cfg, update)
        OmegaConf.update(cfg, key, value, merge=False)
        return cfg
    except (ConfigKeyError, ConfigAttributeError) as error:
        raise ValueError(f"{source}: {_unknown_key(cfg, error)}") from error
    except OmegaConfBaseException as error:
        raise ValueError(f"{source}: {_describe(error)}") from error


def _unknown_key(cfg: DictConfig, error: OmegaConfBaseException) -> str:
    """``unknown key 'x' (did you mean 'y'?)``, the suggestion from the section's own keys."""
    full_key = str(getattr(error, "full_key", "") or "")
    parent, _, name = full_key.rpartition(".")
    node = OmegaConf.select(cfg, parent) if parent else cfg
    known = list(node.keys()) if isinstance(node, DictConfig) else []
    close = difflib.get_close_matches(name, [str(k) for k in known], n=1)
    suggestion = f" (did you mean '{close[0]}'?)" if close else ""
    return f"unknown key '{full_key or name}'{suggestion}"


def _make_writable(cfg: DictConfig) -> None:
    """Clear the read-only flag frozen dataclasses set, on every node: the dataclasses are
    frozen for their users, the config is built by merging into it."""
    OmegaConf.set_readonly(cfg, False)
    for key in cfg:
        value = OmegaConf.select(cfg, str(key), throw_on_missing=False)
        if isinstance(value, DictConfig):
            _make_writable(value)


def _describe(error: OmegaConfBaseException) -> str:
    """The first line of OmegaConf's message (the rest repeats types and keys)."""
    return str(error).splitlines()[0]


def to_object(cfg: DictConfig) -> Any:
    """The config as its dataclass instance (its rules between settings run again).

    Example:
        >>> type(to_object(load_config("eval"))).__name__
        'EvalConfig'
    """
    return OmegaConf.to_object(cfg)


def section[T](cfg: DictConfig, schema: type[T]) -> T:
    """A config section as its dataclass, e.g. the ``ray`` section as the Ray settings.

    Example:
        >>> from oasis_torchrl.config.ray import RayCollectionConfig
        >>> section(load_config("ppo").ray, RayCollectionConfig).num_collectors
        2
    """
    values = OmegaConf.to_container(cfg, resolve=True)
    names = {field.name for field in dataclasses.fields(schema)}
    return schema(**{name: value for name, value in values.items() if name in names})


def save_config(cfg: DictConfig, path: str | Path) -> Path:
    """Write ``cfg`` as YAML (the exact settings of a run, next to its outputs).

    Example:
        >>> import tempfile
        >>> out = save_config(OmegaConf.create({"a": 1}), Path(tempfile.mkdtemp()) / "c.yaml")
        >>> OmegaConf.load(out).a
        1
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    OmegaConf.save(cfg, path)
    return path
