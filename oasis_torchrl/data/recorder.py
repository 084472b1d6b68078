"""Record TorchRL rollouts and collector batches as a LeRobot dataset, one episode per env episode.

Rows of the N env rows of a batch are kept apart: each env row has its own open episode, which
is cut where ``("next", "done")`` is set and otherwise continues into the next batch. How steps
and chunks become rows: :mod:`oasis_torchrl.data.chunk_rows`.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from tensordict import TensorDictBase

from oasis_torchrl.closing import Closing
from oasis_torchrl.config.recording import DEFAULT_CRF, DEFAULT_VCODEC
from oasis_torchrl.data.chunk_rows import (
    RowBatch,
    batch_to_rows,
    frame_size,
    infer_layout,
    rows_per_step,
)
from oasis_torchrl.data.episode_buffer import EpisodeBuffer
from oasis_torchrl.data.features import (
    DatasetLayout,
    Feature,
    build_features,
    check_columns,
)
from oasis_torchrl.data.writer import camera_encoder, open_dataset, whole_fps, write_episode
from oasis_torchrl.protocol import CHUNK, FPS

if TYPE_CHECKING:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

logger = logging.getLogger(__name__)

DEFAULT_BUFFER_BYTES = 1 << 30


class LeRobotRecorder(Closing):
    """Writes batches of env steps as LeRobot episodes; also a TorchRL collector hook.

    The dataset is created (or, with ``append=True``, reopened) at the first batch, whose layout
    fixes the features: pixels ``[..., 4, H, W, 3]`` (``OasisEnv(all_frames=True)``) give one
    row per frame at ``fps``; pixels ``[..., H, W, 3]`` one row per chunk at ``fps / 4``.
    Each batch is checked against the features before anything of it is kept.

    Close it (or use it as a context manager): :meth:`close` always finalizes the dataset. On
    an exception the episodes still running are dropped, so the dataset holds every completed
    episode and nothing half-written.

    Args:
        root: dataset folder (created; must not exist unless ``append``).
        repo_id: LeRobot repo id (default ``local/<folder name>``).
        fps: world-model frame rate of the run.
        image_size: stored ``(height, width)`` (even); default: full resolution.
        vcodec: video codec (``"h264"``, ``"libsvtav1"``, ``"hevc"``).
        crf: video quality (lower is better;
            :data:`~oasis_torchrl.config.recording.DEFAULT_CRF`).
        append: add episodes to the dataset at ``root``.
        max_episodes: stop recording after this many episodes (see :attr:`full`).
        keep_unfinished: on a clean :meth:`close`, also save the episodes still running.
        buffer_bytes: memory for the rows of running episodes, shared by the env rows; an
            episode past its share keeps its frames in a spill file instead.
        spill_dir: folder for spill files (default: beside ``root``).
        privileged: also store each frame's ``privileged_state`` (needs ground truth: the
            embedded server), the target of the oasis policy's auxiliary loss.

    Example (as a collector hook: ``Collector(env, policy, ..., post_collect_hook=recorder)``):
        >>> import tempfile
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisEnv("local", num_envs=2, all_frames=True, max_steps=2,
        ...                server=ServerConfig(width=64, height=48))
        >>> with LeRobotRecorder(Path(tempfile.mkdtemp()) / "drives") as recorder:
        ...     recorder.write(env.rollout(4, break_when_any_done=False))  # episodes completed
        4
        >>> env.close()
    """

    def __init__(
        self,
        root: str | Path,
        *,
        repo_id: str | None = None,
        fps: float = FPS,
        image_size: tuple[int, int] | None = None,
        vcodec: str = DEFAULT_VCODEC,
        crf: float = DEFAULT_CRF,
        append: bool = False,
        max_episodes: int | None = None,
        keep_unfinished: bool = True,
        buffer_bytes: int = DEFAULT_BUFFER_BYTES,
        spill_dir: str | Path | None = None,
        privileged: bool = False,
    ) -> None:
        if max_episodes is not None and max_episodes < 1:
            raise ValueError(f"max_episodes must be >= 1, got {max_episodes}")
        self.root = Path(root)
        self.repo_id = repo_id
        self.fps = whole_fps(fps)
        self.image_size = image_size
        camera_encoder(vcodec, crf)  # a bad codec or quality fails here, not at the first batch
        self.vcodec = vcodec
        self.crf = crf
        self.append = append
        self.max_episodes = max_episodes
        self.keep_unfinished = keep_unfinished
        self.buffer_bytes = buffer_bytes
        self.privileged = privileged
        self.dataset: LeRobotDataset | None = None
        self._existing = (0, 0)  # (episodes, rows) already in an appended dataset
        self.layout: DatasetLayout | None = None
        self._features: dict[str, Feature] = {}
        self._source_size: tuple[int, int] | None = None
        self._spill_root = Path(spill_dir) if spill_dir is not None else self.root.parent
        self._spill_dir: Path | None = None
        self._open: list[EpisodeBuffer | None] = []
        self._closed = False

    @property
    def episodes_written(self) -> int:
        """Episodes this recorder has saved (counted by the dataset itself)."""
        return 0 if self.dataset is None else self.dataset.meta.total_episodes - self._existing[0]

    @property
    def rows_written(self) -> int:
        """Dataset rows this recorder has saved."""
        return 0 if self.dataset is None else self.dataset.meta.total_frames - self._existing[1]

    @property
    def full(self) -> bool:
        """Whether ``max_episodes`` episodes have been written."""
        return self.max_episodes is not None and self.episodes_written >= self.max_episodes

    @property
    def running_episodes(self) -> int:
        """Episodes started and not yet ended."""
        return sum(buffer is not None for buffer in self._open)

    # -- writing ---------------------------------------------------------------------------

    def __call__(self, batch: TensorDictBase) -> TensorDictBase:
        """Record ``batch`` and return it unchanged (a collector ``postproc``/post-collect hook)."""
        self.write(batch)
        return batch

    def write(self, batch: TensorDictBase) -> int:
        """Record a batch of env steps ``[..., T]``; returns the episodes it completed."""
        if self._closed:
            raise RuntimeError("the recorder is closed")
        if self.full:
            return 0
        layout = self.layout or infer_layout(batch, self.image_size, self.privileged)
        features = self._features or build_features(layout)
        rows = batch_to_rows(batch, layout, self._source_size)
        check_columns(rows.columns, features, leading=3)
        if self.layout is None:
            self._start(layout, features, rows_per_step(batch), rows.shape[0])
            self._source_size = frame_size(batch)
        if len(self._open) != rows.shape[0]:
            raise ValueError(
                f"the batch has {rows.shape[0]} env rows, earlier batches had {len(self._open)}"
            )
        before = self.episodes_written
        for step in range(rows.shape[1]):
            for row in range(rows.shape[0]):
                if not self.full:
                    self._record_step(rows, row, step)
        return self.episodes_written - before

    def _start(
        self, layout: DatasetLayout, features: dict[str, Feature], rows_per_step: int, env_rows: int
    ) -> None:
        """Open the dataset for the first batch's layout."""
        if rows_per_step == 1 and self.fps % CHUNK:
            raise ValueError(f"fps {self.fps} is not divisible by {CHUNK} (one row per chunk)")
        dataset_fps = self.fps if rows_per_step > 1 else self.fps // CHUNK
        self.dataset = open_dataset(
            self.root,
            features,
            dataset_fps,
            repo_id=self.repo_id,
            vcodec=self.vcodec,
            crf=self.crf,
            append=self.append,
        )
        self._existing = (self.dataset.meta.total_episodes, self.dataset.meta.total_frames)
        self.layout, self._features = layout, features
        self._spill_dir = Path(
            tempfile.mkdtemp(prefix=f".{self.root.name}-spill-", dir=self._spill_root)
        )
        self._open = [None] * env_rows
        logger.info(
            "recording %s at %d fps (%d rows per step) into %s",
            layout,
            dataset_fps,
            rows_per_step,
            self.root,
        )

    def _record_step(self, rows: RowBatch, row: int, step: int) -> None:
        task, seed = rows.tasks[row][step], int(rows.seeds[row, step])
        episode = self._open[row]
        if episode is not None and (episode.task, episode.seed) != (task, seed):
            logger.warning(
                "env row %d switched to a new episode without a done flag; cutting the old one",
                row,
            )
            self._end(row, save=self.keep_unfinished)
            episode = None
        if episode is None:
            share = self.buffer_bytes // len(self._open)
            episode = EpisodeBuffer(self._spill_dir, self._features, task, seed, share)
            self._open[row] = episode
        episode.append(rows.step(row, step))
        if rows.done[row, step]:
            self._end(row, save=True)

    def _end(self, row: int, *, save: bool) -> None:
        episode, self._open[row] = self._open[row], None
        try:
            if save and not self.full:
                write_episode(self.dataset, episode.rows(), episode.task)
        finally:
            episode.discard()

    # -- ending and closing ----------------------------------------------------------------

    def end_episodes(self, *, save: bool = True) -> None:
        """End every running episode now: save it as it is (no done flag on its last row), or
        drop it. For callers that know their rollout stops here, e.g. a fixed-length evaluation;
        the env rows' next steps then start new episodes."""
        for row, episode in enumerate(self._open):
            if episode is not None:
                self._end(row, save=save)

    def close(self, *, keep_unfinished: bool | None = None) -> None:
        """Save (or drop) the running episodes, then finalize the dataset; always finalizes."""
        if self._closed:
            return
        self._closed = True
        keep = self.keep_unfinished if keep_unfinished is None else keep_unfinished
        try:
            self.end_episodes(save=keep)
        finally:
            for row, episode in enumerate(self._open):
                if episode is not None:
                    episode.discard()
                    self._open[row] = None
            if self._spill_dir is not None:
                shutil.rmtree(self._spill_dir, ignore_errors=True)
            if self.dataset is not None:
                self.dataset.finalize()
            logger.info(
                "closed %s: %d episodes, %d rows written",
                self.root,
                self.episodes_written,
                self.rows_written,
            )

    def __exit__(self, exc_type: type[BaseException] | None, *exc_info: object) -> None:
        self.close(keep_unfinished=None if exc_type is None else False)
