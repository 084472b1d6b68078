"""The shipped policies: trained driving policies the package carries, named ``pretrained:NAME``.

Each is a LeRobot policy folder of type ``oasis`` (``config.json``, ``model.safetensors``) with
its card (``README.md``, the training curve) under ``oasis_torchrl/assets/policies/<NAME>/``.
The environment variable :data:`POLICIES_ENV_VAR` names another folder of such folders instead
(tests, or policies of one's own).
"""

from __future__ import annotations

import os
from pathlib import Path

PREFIX = "pretrained:"
POLICIES_ENV_VAR = "OASIS_PRETRAINED_POLICIES"
"""A folder of shipped-policy folders that replaces the package's own."""
PACKAGE_POLICIES = Path(__file__).resolve().parents[1] / "assets" / "policies"
POLICY_FILES = ("config.json", "model.safetensors")
"""What a folder needs to count as a shipped policy."""


def policies_folder() -> Path:
    """Where the shipped policies are: :data:`POLICIES_ENV_VAR`'s folder, else the package's.

    Example:
        >>> policies_folder().parts[-2:]  # doctest: +SKIP
        ('assets', 'policies')
    """
    override = os.environ.get(POLICIES_ENV_VAR)
    return Path(override) if override else PACKAGE_POLICIES


def shipped_policies() -> dict[str, Path]:
    """Each shipped policy's folder by name, sorted by name.

    Example:
        >>> import tempfile
        >>> os.environ[POLICIES_ENV_VAR] = tempfile.mkdtemp()
        >>> shipped_policies()
        {}
        >>> del os.environ[POLICIES_ENV_VAR]
    """
    folder = policies_folder()
    if not folder.is_dir():
        return {}
    folders = (path for path in sorted(folder.iterdir()) if path.is_dir())
    return {path.name: path for path in folders if all((path / f).is_file() for f in POLICY_FILES)}


def pretrained_path(name: str) -> Path:
    """The folder of the shipped policy ``name`` (``pretrained:`` may lead it).

    Raises:
        ValueError: no shipped policy has that name; the message lists those there are.

    Example:
        >>> import tempfile
        >>> os.environ[POLICIES_ENV_VAR] = tempfile.mkdtemp()
        >>> pretrained_path("pretrained:ppo-scratch")
        Traceback (most recent call last):
        ...
        ValueError: no shipped policy named 'ppo-scratch' (none is shipped yet)
        >>> del os.environ[POLICIES_ENV_VAR]
    """
    name = name.removeprefix(PREFIX)
    shipped = shipped_policies()
    if name not in shipped:
        known = f"shipped: {', '.join(shipped)}" if shipped else "none is shipped yet"
        raise ValueError(f"no shipped policy named {name!r} ({known})")
    return shipped[name]


def resolve_pretrained(spec: str) -> str:
    """``spec`` with a ``pretrained:NAME`` replaced by that policy's folder; any other spec as
    it is.

    Example:
        >>> resolve_pretrained("autopilot")
        'autopilot'
    """
    return str(pretrained_path(spec)) if spec.startswith(PREFIX) else spec
