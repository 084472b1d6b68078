"""LeRobot ``oasis`` policy folders: the driving network saved as one (weights, config,
processors, what ``lerobot-train`` and ``lerobot-eval`` load) and loaded back.

The folder format belongs to the LeRobot plugin (``lerobot_policy_oasis``); this module is the
one place the library reaches it, so the network itself (:mod:`oasis_torchrl.models`) does not
depend on LeRobot.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
from typing import Any

from oasis_torchrl.models import DrivingNet
from oasis_torchrl.models.checkpoint import load_checkpoint, net_from_checkpoint


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
        >>> from oasis_torchrl.models.checkpoint import save_checkpoint
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
