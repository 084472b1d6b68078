"""Files a source tree keeps at its top level and a wheel carries inside the package.

The repository's ``configs/`` (named presets) and ``protos/`` (the ``.proto`` sources) stand at
the top level; the build copies them into the package (``oasis_torchrl/configs/``,
``oasis_torchrl/proto/``, see ``setup.py``), where an installed wheel finds them. A leaf module
(the standard library only): the protocol package and the configs both use it.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


def shipped_files(inside: str, top_level: str, pattern: str) -> list[Path]:
    """The files matching ``pattern`` in the package's ``inside`` folder (an installed wheel),
    else in the source tree's ``top_level`` folder, sorted by name.

    Example:
        >>> [path.name for path in shipped_files("configs", "configs", "ppo_*.yaml")]
        ['ppo_scratch.yaml']
    """
    for folder in (PACKAGE / inside, PACKAGE.parent / top_level):
        matches = sorted(folder.glob(pattern))
        if matches:
            return matches
    return []
