"""``RolloutLogger``: OasisEnv rollouts to rerun, live or as ``.rrd`` files.

One logger, four ways in:

- a plain function on a rollout: ``logger.log_rollout(env.rollout(100))`` (``[N, T]``);
- a collector hook: ``Collector(..., postproc=logger)`` (batches continue episodes);
- a TorchRL transform: ``env.append_transform(RerunTransform(logger))`` (every reset and step);
- a ``FrameConsumer`` of the sync client:
  ``A2VClient(..., frame_consumer=RerunFrameConsumer(logger))``
  (both in :mod:`oasis_torchrl.viz.hooks`, which stand on this module, not the reverse).

Every logged reset or step is one *tick* of 4 world frames on the ``frame`` and ``sim_time``
timelines (layout in :mod:`oasis_torchrl.viz.paths`). Episodes end where they end: once a row is
``done``, nothing more is logged for it until its next reset (an evaluation that steps finished
rows until every row is done logs their last step and stops). Frames are JPEG-encoded and logged
on a background thread by default, at most ``max_pending`` steps behind the env, so memory stays
bounded and the env does not wait for the encoder.
"""

from __future__ import annotations

import atexit
import functools
import weakref
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import torch
from tensordict import TensorDictBase

from oasis_torchrl.client.scenes import SceneLookup
from oasis_torchrl.closing import Closing
from oasis_torchrl.viz.blueprint import RowsLayout
from oasis_torchrl.viz.options import LogOptions
from oasis_torchrl.viz.palette import Policy
from oasis_torchrl.viz.paths import ENV_ROOT
from oasis_torchrl.viz.recording import (
    APPLICATION_ID,
    DEFAULT_MEMORY_LIMIT,
    describe_target,
    is_live,
    layout_first,
    open_recording,
)
from oasis_torchrl.viz.records import StepRecord, batch_rows, read_frames, read_step
from oasis_torchrl.viz.summary import SUMMARY_ROOT, EpisodeSummary
from oasis_torchrl.viz.worker import BoundedWorker
from oasis_torchrl.viz.writer import RecordWriter


class RolloutLogger(Closing):
    """Logs OasisEnv rollouts to rerun: cameras, actions, rewards and terms, collision risk,
    ground truth, depth, episode events and a top-down map, one tab per env row.

    Args:
        target: ``"spawn"`` (start a viewer), a ``rerun+http://host:port/proxy`` URL (a running
            viewer or ``rerun --serve-grpc``), an ``.rrd`` path, or a recording stream another
            logger shares (it stays open when this logger closes).
        options: what to log (:class:`LogOptions`; e.g. ``LogOptions(rows=(0, 5))``).
        scenes: where the top-down view's road and obstacles come from: ``scenes(prompt,
            seed)``, e.g. ``env.scene_source()`` (the env's own server, through the protocol)
            or a :class:`~oasis_torchrl.client.scenes.SceneSource` of a running server. None
            (default) draws the car and its path only, unless a :class:`RerunTransform` hands
            over its env's. Settable later as :attr:`scenes`.
        application_id: rerun application id.
        recording_id: rerun recording id (default: a fresh one).
        memory_limit: memory limit of a spawned viewer; it drops the oldest data beyond it.
        root: the entity root of the rows (``env``; a policy's own in a side-by-side recording).
        summary: where ended episodes go (the summary tab; default: this logger's own).
        send_layout: sends the layout when it changes (default: the default blueprint).
        live: whether the recording goes to a viewer (layouts and plotted values sent as they
            come) rather than a file (values batched, the last layout at :meth:`flush` and
            :meth:`close`); None: a shared stream is live, the logger's own target says it.
            True for a file whose process may end by a signal, with no :meth:`close`: what was
            logged reaches it within a second.
        policy: the policy whose episodes these are, in a side-by-side recording.
        name: whose episodes these are (the policy's name, or the dataset's or robot's where
            there is no policy): every panel's title starts with it (empty: the panels' own
            names alone).

    Example:
        >>> import tempfile, os
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisEnv("local", num_envs=2, server=ServerConfig(width=96, height=64))
        >>> path = os.path.join(tempfile.mkdtemp(), "rollout.rrd")
        >>> with RolloutLogger(path, scenes=env.scene_source()) as rerun_logger:
        ...     rerun_logger.log_rollout(env.rollout(3))
        >>> env.close()
        >>> os.path.getsize(path) > 0
        True
    """

    def __init__(
        self,
        target: str | Path | rr.RecordingStream,
        options: LogOptions | None = None,
        *,
        scenes: SceneLookup | None = None,
        application_id: str = APPLICATION_ID,
        recording_id: str | None = None,
        memory_limit: str = DEFAULT_MEMORY_LIMIT,
        root: str = ENV_ROOT,
        summary: EpisodeSummary | None = None,
        send_layout: Callable[[RowsLayout], None] | None = None,
        live: bool | None = None,
        policy: Policy | None = None,
        name: str = "",
    ) -> None:
        self.options = options if options is not None else LogOptions()
        self._owns_recording = not isinstance(target, rr.RecordingStream)
        owned_file = self._owns_recording and describe_target(target) == "file"
        self._file = Path(target) if owned_file else None
        if live is None:
            live = is_live(target) if self._owns_recording else True
        recording = (
            open_recording(
                target,
                application_id=application_id,
                recording_id=recording_id,
                memory_limit=memory_limit,
            )
            if self._owns_recording
            else target
        )
        self._writer: RecordWriter | None = RecordWriter(
            recording,
            self.options,
            scenes,
            root=root,
            summary=summary,
            send_layout=send_layout,
            live=live,
            policy=policy,
            name=name,
        )
        self._worker = BoundedWorker(self.options.max_pending) if self.options.background else None
        self._tick = 0
        self._pending_starts: np.ndarray | None = None
        self._ended: np.ndarray | None = None
        # Closing before interpreter teardown: rerun cannot flush a stream once its modules
        # are torn down. A weak reference, so an open logger can still be garbage-collected.
        self._close_at_exit = functools.partial(_close_if_alive, weakref.ref(self))
        atexit.register(self._close_at_exit)

    @property
    def scenes(self) -> SceneLookup | None:
        """Where the top-down road comes from (``scenes(prompt, seed)``; None: car and path)."""
        return self._open_writer().scenes

    @scenes.setter
    def scenes(self, scenes: SceneLookup | None) -> None:
        self._open_writer().scenes = scenes

    @property
    def recording(self) -> rr.RecordingStream:
        """This logger's own recording stream (e.g. to log more next to the rollouts)."""
        return self._open_writer().recording

    # -- ways in -----------------------------------------------------------------------------

    def log_reset(
        self,
        obs: TensorDictBase,
        rows: Sequence[int] | None = None,
        *,
        episodes: Sequence[int] | None = None,
    ) -> None:
        """Log a reset observation (batch ``[N]``): ``rows`` (default all) start new episodes,
        numbered ``episodes`` (one per row, e.g. a dataset's episode indices; default: the next
        numbers, in row order)."""
        n = batch_rows(obs)
        rows = list(range(n) if rows is None else rows)
        outside = [row for row in rows if not 0 <= row < n]
        if outside:
            raise ValueError(f"reset rows {outside} are outside the batch of {n} env rows")
        self._pending(n)[rows] = False
        self._ended_rows(n)[rows] = False
        record = read_step(obs, self._logged(n, rows), start=True, **self._read_options())
        if episodes is not None:
            numbers = dict(zip(rows, episodes, strict=True))
            record.episodes = [int(numbers[row]) for row in record.rows]
        self._submit(record)

    def log_step(self, next_obs: TensorDictBase, action: torch.Tensor | None = None) -> None:
        """Log one step: ``next_obs`` is the step's ``"next"`` TensorDict (batch ``[N]``) and
        ``action`` the ``[N, 4, 2]`` (or ``[N, 2]``) action that produced it. Rows whose episode
        ended at an earlier step (and were not reset since) are not logged."""
        n = batch_rows(next_obs)
        ended = self._ended_rows(n)
        running = np.flatnonzero(~ended).tolist()
        record = read_step(
            next_obs, self._logged(n, running), start=False, action=action, **self._read_options()
        )
        done = next_obs.get("done", None)
        if done is not None:
            flags = done.detach().cpu().reshape(n).numpy()
            self._pending(n)[:] = flags
            ended |= flags
        self._submit(record)

    def log_rollout(self, rollout: TensorDictBase, *, new_episodes: bool = True) -> None:
        """Log a rollout ``[N, T]`` (time last, as ``env.rollout`` and collectors return it).

        Args:
            rollout: the rollout; a ``[T]`` rollout is taken as one env row.
            new_episodes: every row starts an episode at ``t = 0`` (``env.rollout`` resets
                first); False continues the episodes of the previous call (collector batches).

        After a row's ``done``, its next root observation starts a new episode (a collector's
        reset) unless it is still ``done`` (an evaluation stepping a finished row on): then
        nothing more is logged for the row.
        """
        if rollout.batch_dims == 1:
            rollout = rollout.unsqueeze(0)
        if rollout.batch_dims != 2:
            raise ValueError(
                f"a rollout must have batch size [N, T] (time last), got {list(rollout.batch_size)}"
            )
        n = int(rollout.batch_size[0])
        if new_episodes:
            self._pending(n)[:] = True
        for t in range(int(rollout.batch_size[1])):
            step = rollout[:, t]
            pending = self._pending(n)
            still_done = step.get("done", None)  # a finished row stepped on, not reset
            if still_done is not None:
                pending = pending & ~still_done.detach().cpu().reshape(n).numpy()
            starting = np.flatnonzero(pending).tolist()
            if starting:
                self.log_reset(step, starting)
            self.log_step(step.get("next"), step.get("action", None))

    def align(self, tick: int) -> None:
        """Log the next reset or step at tick ``tick`` (world frame ``4 * tick``) instead of
        right after the last one: batches of episodes that start at the same tick line up across
        recordings, and across the policies of a side-by-side recording.

        Example:
            >>> import tempfile, os
            >>> rerun_logger = RolloutLogger(os.path.join(tempfile.mkdtemp(), "a.rrd"))
            >>> rerun_logger.align(151)
            >>> rerun_logger.align(3)
            Traceback (most recent call last):
            ...
            ValueError: cannot align to tick 3: tick 151 is already logged or next
            >>> rerun_logger.close()
        """
        if tick < self._tick:
            raise ValueError(
                f"cannot align to tick {tick}: tick {self._tick} is already logged or next"
            )
        self._tick = tick

    def __call__(self, batch: TensorDictBase) -> TensorDictBase:
        """Collector hook (``postproc=logger``): log the batch, continuing episodes; return it."""
        self.log_rollout(batch, new_episodes=False)
        return batch

    def log_frames(
        self, frames: Mapping[str, Sequence[np.ndarray]], *, row: int = 0, start: bool = False
    ) -> None:
        """Log one chunk of client frames (camera -> frames in time order) as ``row``."""
        self._submit(read_frames(frames, row, start))

    # -- lifecycle ---------------------------------------------------------------------------

    def flush(self) -> None:
        """Wait until everything submitted is logged and handed to the sink."""
        writer = self._open_writer()
        self._drain(writer)
        writer.recording.flush()

    def close(self) -> None:
        """Flush and release the sink (an ``.rrd`` file is complete afterwards). Idempotent."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        atexit.unregister(self._close_at_exit)
        try:
            self._drain(writer)
        finally:
            if self._worker is not None:
                self._worker.close()
            writer.recording.flush()
            if self._owns_recording:
                writer.recording.disconnect()
            if self._file is not None:
                layout_first(self._file, writer.latest_layout(), [SUMMARY_ROOT])

    def __getstate__(self) -> dict[str, Any]:
        raise TypeError(
            "RolloutLogger holds a live rerun recording and cannot be pickled; log from the "
            "main process, e.g. as the collector's postproc or on the env before ParallelEnv"
        )

    # -- internals ---------------------------------------------------------------------------

    def _read_options(self) -> dict[str, Any]:
        return {"cameras": self.options.cameras, "depth": self.options.depth}

    def _pending(self, n: int) -> np.ndarray:
        """Rows whose next root observation starts an episode (all, at first)."""
        if self._pending_starts is None or len(self._pending_starts) != n:
            self._pending_starts = np.ones(n, dtype=bool)
        return self._pending_starts

    def _ended_rows(self, n: int) -> np.ndarray:
        """Rows whose episode has ended and that have not been reset since (none, at first)."""
        if self._ended is None or len(self._ended) != n:
            self._ended = np.zeros(n, dtype=bool)
        return self._ended

    def _logged(self, n: int, rows: Sequence[int] | None = None) -> list[int]:
        """The rows to log among ``rows`` (default all): those chosen in the options."""
        chosen = range(n) if self.options.rows is None else self.options.rows
        if max(chosen) >= n:
            raise ValueError(f"LogOptions.rows {self.options.rows} exceed the {n} env rows")
        allowed = set(range(n) if rows is None else rows)
        return [row for row in chosen if row in allowed]

    def _drain(self, writer: RecordWriter) -> None:
        """Write everything queued, then send the buffered series (the worker is idle then;
        series carry their own timestamps, so any thread may send them)."""
        if self._worker is not None:
            self._worker.drain()
        writer.flush()

    def _open_writer(self) -> RecordWriter:
        if self._writer is None:
            raise RuntimeError("this RolloutLogger is closed")
        return self._writer

    def _submit(self, record: StepRecord) -> None:
        writer = self._open_writer()
        if not record.rows:
            return
        tick, self._tick = self._tick, self._tick + 1
        if self._worker is None:
            writer.write(record, tick)
        else:
            self._worker.submit(writer.write, record, tick)


def _close_if_alive(reference: weakref.ref) -> None:
    rollout_logger = reference()
    if rollout_logger is not None:
        rollout_logger.close()
