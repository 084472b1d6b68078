"""YAML configs (Hydra style, as TorchRL's sota-implementations) with ``key=value`` overrides.

A config is ``configs/<name>.yaml`` (or any YAML path) loaded with OmegaConf; overrides are
dotted ``key=value`` strings (``optim.lr=1e-4``, ``env.prompts=[urban,rural]``). The loaded
config is in struct mode: an override or a lookup of a key the YAML does not define is an error
naming the key, so a typo never silently does nothing.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import ConfigAttributeError, ConfigKeyError

logger = logging.getLogger(__name__)

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"
"""The repository's ``configs/`` folder (named configs resolve here)."""


def config_path(name_or_path: str | Path) -> Path:
    """The YAML file of a named config (``"ppo"`` -> ``configs/ppo.yaml``) or an explicit path.

    Example:
        >>> config_path("ppo").name
        'ppo.yaml'
    """
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        candidate = path
    else:
        candidate = CONFIG_DIR / f"{name_or_path}.yaml"
    if not candidate.is_file():
        raise FileNotFoundError(
            f"config {str(name_or_path)!r} not found (looked for {candidate}); pass a YAML path"
        )
    return candidate


def load_config(name_or_path: str | Path, overrides: Sequence[str] = ()) -> DictConfig:
    """Load a config and apply ``key=value`` overrides; interpolations are resolved.

    Example:
        >>> cfg = load_config("ppo", ["optim.lr=0.001", "env.num_envs=2"])
        >>> cfg.optim.lr, cfg.env.num_envs
        (0.001, 2)
        >>> load_config("ppo", ["optim.learning_rate=1"])
        Traceback (most recent call last):
        ...
        ValueError: unknown config key in override 'optim.learning_rate=1' (ppo.yaml)
    """
    path = config_path(name_or_path)
    cfg = OmegaConf.load(path)
    if not isinstance(cfg, DictConfig):
        raise ValueError(f"{path} must hold a mapping at the top level")
    return apply_overrides(_with_defaults(cfg, path), overrides, source=path.name)


def _with_defaults(cfg: DictConfig, path: Path) -> DictConfig:
    """Merge Hydra-style ``defaults: [{section: name}]``: ``configs/<name>.yaml`` becomes
    ``cfg.section`` (values the config itself sets under ``section`` win)."""
    if "defaults" not in cfg:
        return cfg
    defaults = cfg.pop("defaults")
    base = OmegaConf.create()
    for entry in defaults:
        if not isinstance(entry, DictConfig) or len(entry) != 1:
            raise ValueError(f"{path.name}: each defaults entry must be {{section: config}}")
        ((section, name),) = entry.items()
        base[section] = OmegaConf.load(config_path(name))
    return OmegaConf.merge(base, cfg)


def apply_overrides(
    cfg: DictConfig, overrides: Sequence[str], source: str = "config"
) -> DictConfig:
    """A resolved copy of ``cfg`` with dotted ``key=value`` overrides merged, in struct mode.

    Example:
        >>> apply_overrides(OmegaConf.create({"a": {"b": 1}}), ["a.b=2"]).a.b
        2
    """
    merged = OmegaConf.create(OmegaConf.to_container(cfg, resolve=False))
    OmegaConf.set_struct(merged, True)
    for override in overrides:
        if "=" not in override:
            raise ValueError(f"override {override!r} must look like key=value")
        try:
            merged = OmegaConf.merge(merged, OmegaConf.from_dotlist([override]))
        except (ConfigAttributeError, ConfigKeyError) as error:
            raise ValueError(f"unknown config key in override {override!r} ({source})") from error
    OmegaConf.resolve(merged)
    return merged


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
