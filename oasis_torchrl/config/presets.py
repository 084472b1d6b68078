"""Named presets: YAML files of settings that override a command's dataclass defaults.

``--config NAME`` (or ``--config path/to/file.yaml``) on every command loads one before the flags
and ``key=value`` overrides. The presets are the repository's top-level ``configs/`` folder,
which a wheel carries inside the package (:mod:`oasis_torchrl.shipped`).
"""

from __future__ import annotations

from pathlib import Path

from oasis_torchrl.shipped import shipped_files

PRESET_SUFFIX = ".yaml"


def presets() -> dict[str, Path]:
    """Each preset's file by name.

    Example:
        >>> presets()["ppo_scratch"].name
        'ppo_scratch.yaml'
    """
    return {path.stem: path for path in shipped_files("configs", "configs", f"*{PRESET_SUFFIX}")}


def preset_names() -> list[str]:
    """The names ``--config`` knows.

    Example:
        >>> "ppo_scratch" in preset_names()
        True
    """
    return sorted(presets())


def preset_file(config: str | Path) -> Path:
    """The YAML file of ``--config``: a preset's name, or a path (one with a folder or a
    ``.yaml``/``.yml`` suffix, or an existing file).

    Raises:
        ValueError: a name that is no preset, with the names there are.

    Example:
        >>> preset_file("ppo_scratch").name
        'ppo_scratch.yaml'
        >>> preset_file("runs/mine.yaml")
        PosixPath('runs/mine.yaml')
        >>> preset_file("ppo_scratc")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: no preset named 'ppo_scratc'; presets: clone_256, demo, hosted, ...
    """
    path = Path(config)
    if len(path.parts) > 1 or path.suffix in (PRESET_SUFFIX, ".yml") or path.is_file():
        return path
    known = presets()
    if path.name not in known:
        raise ValueError(f"no preset named {path.name!r}; presets: {', '.join(sorted(known))}")
    return known[path.name]
