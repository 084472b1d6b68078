"""The shipped motion network's weights: written by ``oasis-torchrl train motion``, read by the
frames-only reward (:class:`~oasis_torchrl.rewards.motion.MotionReward`).

``env.reward.motion_model`` names them: ``small`` is the file shipped in the package
(``oasis_torchrl/assets/motion_small.pt``), anything else a path to another weights file (one a
user fine-tuned on their own recordings, say).
"""

from __future__ import annotations

import dataclasses
import logging
import os
from importlib import resources
from pathlib import Path
from typing import Any

from oasis_torchrl.models.motion import MotionNet, MotionNetConfig
from oasis_torchrl.rewards.depth_sources import error_cause
from oasis_torchrl.rewards.weights_file import check_fits, read_weights, write_weights

logger = logging.getLogger(__name__)

SMALL_MOTION_MODEL = "small"
"""The ``env.reward.motion_model`` value that names the shipped network."""
MOTION_WEIGHTS_FORMAT = "oasis-torchrl motion net 1"
"""The ``format`` entry of a weights file, checked on load."""
SHIPPED_MOTION_WEIGHTS = "motion_small.pt"
"""The shipped weights' file name in the package's ``assets`` folder."""


class MotionModelError(ValueError):
    """A motion network's weights that cannot be loaded (one line: the file, the cause, what to
    use instead)."""


def save_motion_weights(
    net: MotionNet, path: str | os.PathLike[str], meta: dict[str, Any] | None = None
) -> Path:
    """Write ``net``'s weights and shape (and ``meta``: how it was trained) to ``path``.

    >>> import tempfile
    >>> net = MotionNet(MotionNetConfig(channels=(4, 4)))
    >>> path = save_motion_weights(net, f"{tempfile.mkdtemp()}/m.pt", {"seed": 0})
    >>> load_motion_net(str(path)).cfg.channels
    (4, 4)
    """
    return write_weights(path, MOTION_WEIGHTS_FORMAT, net, dataclasses.asdict(net.cfg), meta)


def motion_weights_path(model: str) -> Path:
    """The weights file ``env.reward.motion_model`` names.

    >>> motion_weights_path("small").name
    'motion_small.pt'
    """
    if model == SMALL_MOTION_MODEL:
        return Path(str(resources.files("oasis_torchrl") / "assets" / SHIPPED_MOTION_WEIGHTS))
    return Path(model)


def load_motion_net(model: str = SMALL_MOTION_MODEL) -> MotionNet:
    """The motion network ``model`` names (``small`` or a weights file), in inference mode.

    A file that cannot be loaded raises :class:`MotionModelError`, one line naming the file, the
    cause and the alternatives.

    >>> load_motion_net().cfg.horizon
    5
    """
    file = motion_weights_path(model)
    try:
        payload = read_weights(file, MOTION_WEIGHTS_FORMAT)
        values = payload["config"]
        cfg = MotionNetConfig(
            image_size=tuple(values["image_size"]),
            channels=tuple(values["channels"]),
            hidden=int(values["hidden"]),
            horizon=int(values["horizon"]),
        )
        net = MotionNet(cfg)
        check_fits(net, payload["state_dict"])
        net.load_state_dict(payload["state_dict"])
    except Exception as error:  # any failure to read the file is reported the same way
        raise MotionModelError(
            f"motion network {str(file)!r} cannot be loaded: {error_cause(error)}; use the "
            "shipped weights (env.reward.motion_model=small) or retrain with "
            "'oasis-torchrl train motion'"
        ) from None
    logger.debug("loaded motion network %s", file)
    return net.eval()
