"""The shipped small depth network as a depth source: offline nearness for the frames-only reward.

:class:`SmallDepth` runs :class:`~oasis_torchrl.models.depth.DepthNet` on a camera's frames;
:func:`load_small_depth` reads the weights shipped with the package
(``oasis_torchrl/assets/depth_small.pt``, made by ``oasis-torchrl train depth``) or another
weights file; :func:`depth_source_for` maps the ``env.reward.depth_model`` setting (``small`` or
a transformers model) to its source.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from importlib import resources
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase

from oasis_torchrl.models.depth import DepthNet, config_from_dict
from oasis_torchrl.rewards.depth_sources import (
    DepthModelError,
    DepthSource,
    MonocularDepth,
    check_camera,
    error_cause,
    read_pixels,
)
from oasis_torchrl.rewards.weights_file import check_fits, read_weights, write_weights

logger = logging.getLogger(__name__)

SMALL_DEPTH_MODEL = "small"
"""The ``env.reward.depth_model`` value that names the shipped network."""
WEIGHTS_FORMAT = "oasis-torchrl depth net 1"
"""The ``format`` entry of a weights file, checked on load."""
SHIPPED_WEIGHTS = "depth_small.pt"
"""The shipped weights' file name in the package's ``assets`` folder."""


def shipped_weights() -> Path:
    """Where the package's own weights file is.

    >>> shipped_weights().name
    'depth_small.pt'
    """
    return Path(str(resources.files("oasis_torchrl") / "assets" / SHIPPED_WEIGHTS))


class SmallDepth:
    """Nearness ``[N, H, W]`` of a camera's frames from a :class:`DepthNet`.

    Frames of another size than the network's ``image_size`` are resized to it (area averaging
    when shrinking), and the map is resized back bilinearly, so any endpoint's frames work.
    The network runs in inference mode on the frames' device.

    >>> from tensordict import TensorDict
    >>> from oasis_torchrl.models.depth import DepthNetConfig
    >>> source = SmallDepth(DepthNet(DepthNetConfig(channels=(4, 8))), image_size=(8, 12))
    >>> td = TensorDict({("pixels", "front"): torch.zeros(2, 16, 24, 3, dtype=torch.uint8)}, [2])
    >>> source(td).shape
    torch.Size([2, 16, 24])
    """

    def __init__(self, net: DepthNet, image_size: tuple[int, int], camera: str = "front") -> None:
        divisor = net.config.divisor
        if len(image_size) != 2 or any(side <= 0 or side % divisor for side in image_size):
            raise ValueError(
                f"image_size must be (height, width), multiples of {divisor}, got {image_size}"
            )
        self.net = net.eval()
        self.image_size = (int(image_size[0]), int(image_size[1]))
        self.camera = check_camera(camera)

    def __call__(self, td: TensorDictBase) -> torch.Tensor:
        """One batched forward over the camera's N frames; float32 nearness ``[N, H, W]``."""
        rgb = read_pixels(td, self.camera, type(self).__name__)
        return self.nearness(rgb)

    def nearness(self, rgb: torch.Tensor) -> torch.Tensor:
        """Nearness ``[N, H, W]`` of uint8 frames ``[N, H, W, 3]``."""
        size = tuple(rgb.shape[1:3])
        if self.net.head.weight.device != rgb.device:
            self.net.to(rgb.device)
        with torch.inference_mode():
            nearness = self.net(_resize_frames(rgb, self.image_size))
        # Outside inference mode the result is an ordinary tensor callers may change in place.
        nearness = nearness.clone()
        if size == self.image_size:
            return nearness
        return F.interpolate(
            nearness.unsqueeze(1), size=size, mode="bilinear", align_corners=False
        ).squeeze(1)


def _resize_frames(rgb: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    if tuple(rgb.shape[1:3]) == size:
        return rgb
    images = rgb.permute(0, 3, 1, 2).float()
    shrink = size[0] <= rgb.shape[1] and size[1] <= rgb.shape[2]
    mode = "area" if shrink else "bilinear"
    resized = F.interpolate(images, size=size, mode=mode)
    return resized.round_().clamp_(0, 255).to(torch.uint8).permute(0, 2, 3, 1).contiguous()


def save_weights(
    path: str | os.PathLike[str],
    net: DepthNet,
    image_size: tuple[int, int],
    meta: dict[str, Any] | None = None,
) -> Path:
    """Write ``net``'s weights, shape and input size (and ``meta``: how it was trained) to
    ``path``, loadable by :func:`load_small_depth`; returns the path.

    >>> import tempfile
    >>> from oasis_torchrl.models.depth import DepthNetConfig
    >>> folder = tempfile.mkdtemp()
    >>> net = DepthNet(DepthNetConfig(channels=(4, 8)))
    >>> path = save_weights(f"{folder}/d.pt", net, (8, 12), {"seed": 0})
    >>> load_small_depth(path=path).image_size
    (8, 12)
    """
    config = dataclasses.asdict(net.config)
    return write_weights(path, WEIGHTS_FORMAT, net, config, meta, image_size=list(image_size))


def load_small_depth(
    camera: str = "front", path: str | os.PathLike[str] | None = None
) -> SmallDepth:
    """The small depth network as a depth source: the shipped weights, or those at ``path``.

    A file that cannot be loaded (missing, not a weights file, weights of another shape) raises
    :class:`~oasis_torchrl.rewards.depth_sources.DepthModelError`, one line naming the file, the
    cause and what to use instead.

    >>> source = load_small_depth()
    >>> source.camera, source.image_size
    ('front', (64, 96))
    """
    file = Path(path) if path is not None else shipped_weights()
    try:
        payload = read_weights(file, WEIGHTS_FORMAT)
        net = DepthNet(config_from_dict(payload["config"]))
        check_fits(net, payload["state_dict"])
        net.load_state_dict(payload["state_dict"])
        image_size = tuple(payload["image_size"])
    except Exception as error:  # any failure to read the file is reported the same way
        raise DepthModelError(
            f"small depth network {str(file)!r} cannot be loaded: {error_cause(error)}; "
            f"use the shipped weights (path=None), retrain with 'oasis-torchrl train depth', "
            f"or a transformers model (env.reward.depth_model=<model id>)"
        ) from None
    logger.debug("loaded small depth network %s (%s)", file, payload.get("meta", {}))
    return SmallDepth(net, image_size, camera)


def depth_source_for(model: str, camera: str = "front") -> DepthSource:
    """The depth source the ``env.reward.depth_model`` setting names: ``small`` is the shipped
    network (:func:`load_small_depth`), anything else a transformers model id or folder
    (:class:`~oasis_torchrl.rewards.depth_sources.MonocularDepth`, loaded on first use).

    >>> type(depth_source_for("small")).__name__
    'SmallDepth'
    >>> type(depth_source_for("depth-anything/Depth-Anything-V2-Small-hf")).__name__
    'MonocularDepth'
    """
    if model == SMALL_DEPTH_MODEL:
        return load_small_depth(camera)
    return MonocularDepth(model, camera=camera)
