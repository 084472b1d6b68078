"""Per-worker LeRobot shards: every Ray collector records its own batches into its own dataset.

A :class:`ShardRecorder` is the ``post_collect_hook`` of one remote collector: it runs inside the
worker, wraps a :class:`~oasis_torchrl.data.LeRobotRecorder` and writes ``<root>/worker-<i>-
part-<j>``. A part is finalized when the run closes it or, with ``part_batches``, every that many
batches (episodes still running are then saved as they are, and continue in the next part); a
finalized part gets a :data:`COMPLETE_MARKER` file, so a merge takes exactly the readable parts.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from tensordict import TensorDictBase

from oasis_torchrl.data import LeRobotRecorder

logger = logging.getLogger(__name__)

COMPLETE_MARKER = ".shard-complete"
"""File written into a shard part once its dataset is finalized."""


def shard_name(worker: int, part: int) -> str:
    """Folder name of a worker's shard part.

    Example:
        >>> shard_name(1, 0)
        'worker-001-part-0000'
    """
    return f"worker-{worker:03d}-part-{part:04d}"


class ShardRecorder:
    """Records one worker's collector batches into finalized LeRobot shard parts.

    Picklable until first used (it is shipped to the Ray actor as a collector hook).

    Args:
        root: folder holding the shards of the run.
        worker: index of the collector (names the shard).
        part_batches: finalize and start a new part every that many batches (0: never).
        **recorder_kwargs: :class:`~oasis_torchrl.data.LeRobotRecorder` arguments (``fps``,
            ``image_size``, ``vcodec``, ...).

    Example:
        >>> import tempfile
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisEnv("local", num_envs=1, all_frames=True, max_steps=2,
        ...                server=ServerConfig(width=64, height=48))
        >>> shards = ShardRecorder(tempfile.mkdtemp(), worker=0)
        >>> _ = shards(env.rollout(2, break_when_any_done=False))
        >>> shards.close()
        1
        >>> env.close()
    """

    def __init__(
        self, root: str | Path, worker: int, *, part_batches: int = 0, **recorder_kwargs: Any
    ) -> None:
        if part_batches < 0:
            raise ValueError(f"part_batches must be >= 0, got {part_batches}")
        self.root = Path(root)
        self.worker = worker
        self.part_batches = part_batches
        self.recorder_kwargs = recorder_kwargs
        self.episodes = 0
        self._part = 0
        self._batches_in_part = 0
        self._recorder: LeRobotRecorder | None = None

    def __call__(self, batch: TensorDictBase) -> TensorDictBase:
        """Record ``batch`` (a collector's ``[N, T]`` output) and return it unchanged."""
        if self._recorder is None:
            self._recorder = LeRobotRecorder(
                self.root / shard_name(self.worker, self._part), **self.recorder_kwargs
            )
        self._recorder.write(batch)
        self._batches_in_part += 1
        if self.part_batches and self._batches_in_part >= self.part_batches:
            self._close_part()
        return batch

    def _close_part(self) -> None:
        recorder, self._recorder = self._recorder, None
        self._batches_in_part = 0
        if recorder is None:
            return
        recorder.close(keep_unfinished=True)
        self.episodes += recorder.episodes_written
        if recorder.dataset is not None:
            (recorder.root / COMPLETE_MARKER).touch()
            logger.info("worker %d finalized shard %s", self.worker, recorder.root)
        self._part += 1

    def close(self) -> int:
        """Finalize the open part; returns the episodes this worker recorded in all parts."""
        self._close_part()
        return self.episodes
