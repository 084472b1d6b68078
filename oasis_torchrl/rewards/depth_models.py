"""The depth source of the setting ``env.reward.depth_model``, loaded at its first use:
``small`` (the network shipped with the package, the frames-only reward's default, offline) or
a transformers depth model's hub id or folder (the reference's Depth-Anything-V2-Small)."""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase

from oasis_torchrl.rewards.depth_net import SMALL_DEPTH_MODEL, depth_source_for
from oasis_torchrl.rewards.depth_sources import DepthSource, check_camera


class NamedDepth:
    """The depth source named ``model`` (:func:`~oasis_torchrl.rewards.depth_net.depth_source_for`),
    loaded at its first call: an env that is built, pickled to its workers or never stepped
    loads no network.

    Example:
        >>> source = NamedDepth()
        >>> source.model, source.camera, source.is_loaded
        ('small', 'front', False)
    """

    def __init__(self, model: str = SMALL_DEPTH_MODEL, camera: str = "front") -> None:
        self.model = model
        self.camera = check_camera(camera)
        self._source: DepthSource | None = None

    @property
    def is_loaded(self) -> bool:
        """Whether the named source is loaded."""
        return self._source is not None

    def __getstate__(self) -> dict[str, Any]:
        return dict(self.__dict__, _source=None)  # each process loads its own

    def __call__(self, td: TensorDictBase) -> torch.Tensor:
        """Nearness ``[N, H, W]`` of the camera's frames from the named source."""
        if self._source is None:
            self._source = depth_source_for(self.model, self.camera)
        return self._source(td)
