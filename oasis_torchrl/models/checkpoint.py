"""Checkpoints: PPO training state, and the driving network in both ecosystems' formats.

- A PPO checkpoint is one ``torch.save`` file: network config and weights, optimizer state,
  iteration, env steps collected and the run's config (everything :func:`train_ppo` needs to
  resume). Written atomically, so an interrupted save never leaves a broken ``latest.pt``.
- A LeRobot policy folder (``config.json``, ``model.safetensors``, processors) is what
  behaviour cloning and ``lerobot-train`` write; :func:`export_lerobot` writes one from any
  network, so PPO policies also load in LeRobot. Both need the ``lerobot_policy_oasis`` plugin.

:func:`load_net` opens either kind.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
from pathlib import Path
from typing import Any

import torch

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
    partial = path.with_name(path.name + ".partial")
    torch.save(payload, partial)
    os.replace(partial, path)
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


def lerobot_plugin() -> Any:
    """The ``lerobot_policy_oasis`` plugin module, or an ImportError saying how to install it.

    Example:
        >>> lerobot_plugin().POLICY_TYPE
        'oasis'
    """
    try:
        import lerobot_policy_oasis
    except ImportError as error:
        raise ImportError(
            "LeRobot policy folders need the plugin: pip install -e policies/ "
            "(the lerobot_policy_oasis distribution)"
        ) from error
    return lerobot_policy_oasis


def net_from_lerobot(path: str | Path) -> DrivingNet:
    """The network of a LeRobot ``oasis`` policy folder (``save_pretrained`` output).

    Raises:
        ValueError: the policy normalises its inputs or actions (a TorchRL env feeds raw
            values, so only ``IDENTITY`` normalisation transfers as is).

    Example:
        >>> import tempfile
        >>> folder = export_lerobot(DrivingNet(), Path(tempfile.mkdtemp()) / "policy")
        >>> net_from_lerobot(folder).config.image_size
        (64, 96)
    """
    plugin = lerobot_plugin()
    # LeRobot prints a progress line; stdout may carry a command's JSON result.
    with contextlib.redirect_stdout(io.StringIO()):
        policy = plugin.OasisPolicy.from_pretrained(str(path))
    modes = {
        str(key): getattr(mode, "value", mode)
        for key, mode in policy.config.normalization_mapping.items()
    }
    if any(mode != "IDENTITY" for mode in modes.values()):
        raise ValueError(
            f"{path} was trained with normalization {modes}; only IDENTITY transfers to TorchRL "
            "unchanged (retrain with the default normalization_mapping)"
        )
    return policy.model


def load_net(path: str | Path) -> DrivingNet:
    """A :class:`DrivingNet` from a PPO checkpoint file or a LeRobot policy folder.

    Example:
        >>> import tempfile
        >>> path = save_checkpoint(Path(tempfile.mkdtemp()) / "c.pt", DrivingNet())
        >>> load_net(path).config.cameras
        ('left_forward', 'front', 'right_forward')
    """
    path = Path(path)
    if path.is_dir():
        return net_from_lerobot(path)
    return net_from_checkpoint(load_checkpoint(path))


def export_lerobot(net: DrivingNet, path: str | Path) -> Path:
    """Write ``net`` as a LeRobot ``oasis`` policy folder (weights, config, processors).

    Example:
        >>> import tempfile
        >>> out = export_lerobot(DrivingNet(), Path(tempfile.mkdtemp()) / "policy")
        >>> sorted(p.name for p in out.iterdir())[:2]
        ['config.json', 'model.safetensors']
    """
    plugin = lerobot_plugin()
    if net.config.critic_inputs or net.config.aux_outputs:
        net = net.with_training_heads(0, 0)  # LeRobot only acts: no critic, no privileged state
    config = plugin.OasisConfig.from_net_config(net.config)
    policy = plugin.OasisPolicy(config)
    policy.model.load_state_dict(net.state_dict())
    path = Path(path)
    policy.save_pretrained(path)
    preprocessor, postprocessor = plugin.make_oasis_pre_post_processors(config)
    preprocessor.save_pretrained(path)
    postprocessor.save_pretrained(path)
    return path
