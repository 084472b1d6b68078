"""Depth sources by name, the setting ``env.reward.depth_model``: ``small`` (the network shipped
with the package, :mod:`oasis_torchrl.rewards.depth_net`: the frames-only reward's default,
offline) or a transformers depth model's hub id or folder (the reference's
Depth-Anything-V2-Small for the hosted service)."""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDictBase

from oasis_torchrl.rewards.depth_sources import DepthSource, MonocularDepth, check_camera

SMALL_DEPTH_MODEL = "small"
"""The shipped small depth network."""


def load_depth_source(model: str, camera: str = "front") -> DepthSource:
    """The depth source named ``model``, loaded now (a transformers model at its first call).

    Example:
        >>> type(load_depth_source("depth-anything/Depth-Anything-V2-Small-hf")).__name__
        'MonocularDepth'
    """
    if model != SMALL_DEPTH_MODEL:
        return MonocularDepth(model, camera=camera)
    from oasis_torchrl.rewards.depth_net import load_small_depth

    return load_small_depth(camera=camera)


class NamedDepth:
    """The depth source named ``model``, loaded at its first call: an env that is built,
    pickled to its workers or never stepped loads no network.

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
            self._source = load_depth_source(self.model, self.camera)
        return self._source(td)
