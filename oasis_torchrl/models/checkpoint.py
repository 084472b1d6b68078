"""PPO checkpoints: one ``torch.save`` file with the network's config and weights, the
optimizer state, iteration, env steps collected and the run's config (everything
:func:`~oasis_torchrl.train.ppo.train_ppo` needs to resume). Written atomically, so an
interrupted save never leaves a broken ``latest.pt``.

The network as a LeRobot policy folder: :mod:`oasis_torchrl.drivers.folders`.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import torch

from oasis_torchrl.atomic import written_whole
from oasis_torchrl.models.config import DrivingNetConfig
from oasis_torchrl.models.network import DrivingNet

logger = logging.getLogger(__name__)

CHECKPOINT_VERSION = 1
LATEST = "latest.pt"
BEST = "best.pt"  # the policy PPO keeps when evaluations on selection seeds choose it


def save_checkpoint(path: str | Path, net: DrivingNet, **state: Any) -> Path:
    """Save ``net`` (config and weights) plus any training ``state`` to ``path``, atomically.

    Example:
        >>> import tempfile
        >>> path = save_checkpoint(Path(tempfile.mkdtemp()) / "c.pt", DrivingNet(), iteration=3)
        >>> load_checkpoint(path)["iteration"]
        3
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "version": CHECKPOINT_VERSION,
        "net_config": net.config.to_dict(),
        "net_state": net.state_dict(),
        **state,
    }
    with written_whole(path) as partial:
        torch.save(payload, partial)
    return path


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """The dict a :func:`save_checkpoint` file holds (on the CPU).

    Example:
        >>> import tempfile
        >>> path = save_checkpoint(Path(tempfile.mkdtemp()) / "c.pt", DrivingNet(), frames=8)
        >>> sorted(load_checkpoint(path))
        ['frames', 'net_config', 'net_state', 'version']
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    payload = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(payload, dict) or payload.get("version") != CHECKPOINT_VERSION:
        raise ValueError(
            f"{path} is not an oasis-torchrl checkpoint (version {CHECKPOINT_VERSION})"
        )
    return payload


def net_from_checkpoint(payload: dict[str, Any]) -> DrivingNet:
    """Rebuild the network of a loaded checkpoint.

    Example:
        >>> import tempfile
        >>> path = save_checkpoint(Path(tempfile.mkdtemp()) / "c.pt", DrivingNet())
        >>> net_from_checkpoint(load_checkpoint(path)).config.frames
        2
    """
    net = DrivingNet(DrivingNetConfig.from_dict(payload["net_config"]))
    net.load_state_dict(payload["net_state"])
    return net
