"""Adapters that feed a :class:`~oasis_torchrl.viz.RolloutLogger`: a TorchRL transform and a
``FrameConsumer`` for the sync client. (The collector hook is the logger itself:
``postproc=logger``.)"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from tensordict import TensorDictBase
from torchrl.envs import EnvBase, Transform

from oasis_torchrl.client.scenes import SceneLookup
from oasis_torchrl.viz.logger import RolloutLogger


def reset_rows(tensordict: TensorDictBase | None, n: int) -> list[int]:
    """Rows a reset applies to: those set in the ``"_reset"`` mask, else all ``n``.

    Example:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> mask = torch.tensor([[False], [True], [True]])
        >>> reset_rows(TensorDict({"_reset": mask}, [3]), 3)
        [1, 2]
    """
    mask = None if tensordict is None else tensordict.get("_reset", None)
    if mask is None:
        return list(range(n))
    return mask.reshape(n).nonzero().flatten().tolist()


class RerunTransform(Transform):
    """Logs every reset and step of the env it is appended to; changes nothing.

    A logger without a scene source gets its env's (``env.scene_source()``, the env's own
    server asked through the protocol) at the first reset, so the top-down view shows the road.
    Append it before transforms that drop or convert ``("pixels", camera)`` (it reads the raw
    uint8 frames). It logs in the process that steps the env, so use it on a single env (or in
    the main process), not inside ``ParallelEnv`` workers.

    Example:
        >>> import tempfile, os
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> from oasis_torchrl.viz import RolloutLogger
        >>> rerun_logger = RolloutLogger(os.path.join(tempfile.mkdtemp(), "run.rrd"))
        >>> env = OasisEnv("local", 2, server=ServerConfig(width=96, height=64))
        >>> env = env.append_transform(RerunTransform(rerun_logger))
        >>> _ = env.rollout(2)
        >>> env.close(); rerun_logger.close()
    """

    def __init__(self, logger: RolloutLogger) -> None:
        super().__init__(in_keys=[], out_keys=[])
        self.logger = logger

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        if self.logger.scenes is None:
            self.logger.scenes = _scene_source_of(self.parent)
        rows = reset_rows(tensordict, int(tensordict_reset.batch_size[0]))
        self.logger.log_reset(tensordict_reset, rows)
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        self.logger.log_step(next_tensordict, tensordict.get("action", None))
        return next_tensordict


def _scene_source_of(env: EnvBase | None) -> SceneLookup | None:
    """The scene source of the env under a transform (an OasisEnv's), if it has one."""
    base = getattr(env, "base_env", env)
    scene_source = getattr(base, "scene_source", None)
    return scene_source() if callable(scene_source) else None


class RerunFrameConsumer:
    """A ``FrameConsumer`` for :class:`~oasis_torchrl.client.A2VClient`: every chunk of frames
    goes to the logger as env row ``row``; a new clip (a Prompt) starts a new episode.

    The client passes frames only, so this logs the cameras and episode starts (no actions,
    rewards or ground truth).

    Example:
        >>> import tempfile, os
        >>> from oasis_torchrl.viz import RolloutLogger
        >>> rerun_logger = RolloutLogger(os.path.join(tempfile.mkdtemp(), "client.rrd"))
        >>> consumer = RerunFrameConsumer(rerun_logger, row=0)
        >>> consumer.new_clip()
        >>> consumer.submit({"front": [np.zeros((64, 96, 3), np.uint8)] * 4})
        >>> rerun_logger.close()
    """

    def __init__(self, logger: RolloutLogger, row: int = 0) -> None:
        if row < 0:
            raise ValueError(f"row must be >= 0, got {row}")
        self.logger = logger
        self.row = row
        self._new_clip = True

    def submit(self, frames: Mapping[str, Sequence[np.ndarray]]) -> None:
        """Log one chunk (camera -> frames in time order)."""
        self.logger.log_frames(frames, row=self.row, start=self._new_clip)
        self._new_clip = False

    def new_clip(self) -> None:
        """The next chunk starts a new episode (the client sent a Prompt)."""
        self._new_clip = True
