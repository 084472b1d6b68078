"""Per-worker LeRobot shards: every Ray collector records its own batches into its own dataset.

A :class:`ShardRecorder` is the ``post_collect_hook`` of one remote collector: it runs inside the
worker, wraps a :class:`~oasis_torchrl.data.LeRobotRecorder` and writes ``<root>/worker-<i>-
part-<j>``. A part is finalized when the run closes it or, with ``part_batches``, every that many
batches (episodes still running are then saved as they are, and continue in the next part). A
part is written under a hidden partial name and appears under its own only once finalized
(:mod:`oasis_torchrl.atomic`), so a merge takes exactly the readable parts.
The episodes still running when the run closes the last part are kept or dropped as the
recorder's ``keep_unfinished`` says.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import datasets
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from oasis_torchrl.atomic import fresh_partial, publish
from oasis_torchrl.data import LeRobotRecorder

logger = logging.getLogger(__name__)


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
        max_episodes: record at most this many episodes over all parts (None: no limit; 0:
            none, see :attr:`full`).
        batch_keys: after recording, strip each batch in place to these keys, so only they
            travel on from the worker (None: leave batches whole; ``()``: keep just the shape).
        **recorder_kwargs: :class:`~oasis_torchrl.data.LeRobotRecorder` arguments (``fps``,
            ``image_size``, ``vcodec``, ``crf``, ``keep_unfinished``, ...).

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
        self,
        root: str | Path,
        worker: int,
        *,
        part_batches: int = 0,
        max_episodes: int | None = None,
        batch_keys: Sequence[NestedKey] | None = None,
        **recorder_kwargs: Any,
    ) -> None:
        if part_batches < 0:
            raise ValueError(f"part_batches must be >= 0, got {part_batches}")
        if max_episodes is not None and max_episodes < 0:
            raise ValueError(f"max_episodes must be >= 0, got {max_episodes}")
        self.root = Path(root)
        self.worker = worker
        self.part_batches = part_batches
        self.max_episodes = max_episodes
        self.batch_keys = None if batch_keys is None else list(batch_keys)
        self.recorder_kwargs = recorder_kwargs
        self.episodes = 0
        self._part = 0
        self._batches_in_part = 0
        self._recorder: LeRobotRecorder | None = None

    @property
    def episodes_written(self) -> int:
        """Episodes saved so far, in the finalized parts and the open one."""
        open_part = 0 if self._recorder is None else self._recorder.episodes_written
        return self.episodes + open_part

    @property
    def full(self) -> bool:
        """Whether ``max_episodes`` episodes have been saved (further batches are not recorded)."""
        return self.max_episodes is not None and self.episodes_written >= self.max_episodes

    def __call__(self, batch: TensorDictBase) -> TensorDictBase:
        """Record ``batch`` (a collector's ``[N, T]`` output); returns it, stripped in place to
        ``batch_keys`` if set."""
        if not self.full:
            self._write(batch)
        if self.batch_keys is not None:
            batch.select(*self.batch_keys, inplace=True)
        return batch

    def _write(self, batch: TensorDictBase) -> None:
        if self._recorder is None:
            datasets.disable_progress_bars()  # a worker's bars reach the driver as log lines
            remaining = None if self.max_episodes is None else self.max_episodes - self.episodes
            self._recorder = LeRobotRecorder(
                fresh_partial(self._part_root),
                max_episodes=remaining,
                **self.recorder_kwargs,
            )
        self._recorder.write(batch)
        self._batches_in_part += 1
        if self.part_batches and self._batches_in_part >= self.part_batches:
            self._close_part(keep_unfinished=True)  # they go on in the next part

    def _close_part(self, *, keep_unfinished: bool | None) -> None:
        recorder, self._recorder = self._recorder, None
        self._batches_in_part = 0
        if recorder is None:
            return
        recorder.close(keep_unfinished=keep_unfinished)
        self.episodes += recorder.episodes_written
        if recorder.dataset is not None:
            publish(self._part_root)
            logger.info("worker %d finalized shard %s", self.worker, self._part_root)
        self._part += 1

    @property
    def _part_root(self) -> Path:
        return self.root / shard_name(self.worker, self._part)

    def close(self) -> int:
        """Finalize the open part (its running episodes kept or dropped as the recorder's
        ``keep_unfinished`` says); returns the episodes this worker recorded in all parts."""
        self._close_part(keep_unfinished=None)
        return self.episodes
