"""Where a recording goes: a spawned viewer, a running viewer or server (gRPC), or an ``.rrd`` file.

Each logger owns its own ``rr.RecordingStream`` (never rerun's global recording), so several
loggers coexist in one process. Memory stays bounded on long runs: an ``.rrd`` sink streams to
disk; a viewer drops its oldest data at its memory limit (``memory_limit`` for a spawned viewer,
``rerun --memory-limit 4GB`` for one you start yourself).

A file's data is batched into chunks of up to :data:`FILE_BATCHING` (every chunk carries its
schema: rerun's default batching, 200 ms, leaves a slowly stepped evaluation's file with chunks
of a row or two, mostly schemas); a viewer gets data as it comes. A layout goes to a viewer as
soon as it changes, to a file once, when it is flushed (:class:`LayoutSender`): a file is read
whole, and each layout of a recording with many tabs weighs as much as seconds of its video.
A viewer shows a file as it reads it, while the final layout and the summary are only known at
the end: :func:`layout_first` rewrites a finished file with them first.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Sequence
from datetime import timedelta
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

logger = logging.getLogger(__name__)

SPAWN = "spawn"
"""Target that starts a native viewer (or reuses the one already listening on its port)."""
GRPC_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
APPLICATION_ID = "oasis_torchrl"
DEFAULT_MEMORY_LIMIT = "25%"
FILE_BATCHING = rr.ChunkBatcherConfig(flush_tick=timedelta(seconds=60), flush_num_bytes=16 << 20)
"""How an ``.rrd`` file's data is batched into chunks: a batch is written after 60 s or at
16 MiB, whichever comes first (what the logger holds in memory before it writes)."""


def describe_target(target: str | Path) -> str:
    """``"spawn"``, ``"grpc"`` or ``"file"``; a ValueError names a target that is none of them.

    Example:
        >>> [describe_target(t) for t in ("spawn", "rerun+http://127.0.0.1:9876/proxy", "a.rrd")]
        ['spawn', 'grpc', 'file']
    """
    text = str(target)
    if text == SPAWN:
        return "spawn"
    if text.startswith(GRPC_SCHEMES):
        return "grpc"
    if text.endswith(".rrd"):
        return "file"
    raise ValueError(
        f"rerun target must be 'spawn', a gRPC URL starting with one of {GRPC_SCHEMES} "
        f"(e.g. rerun+http://127.0.0.1:9876/proxy) or a path ending in .rrd, got {text!r}"
    )


def open_recording(
    target: str | Path,
    *,
    application_id: str = APPLICATION_ID,
    recording_id: str | None = None,
    memory_limit: str = DEFAULT_MEMORY_LIMIT,
    blueprint: rrb.Blueprint | None = None,
) -> rr.RecordingStream:
    """A new recording stream connected to ``target``.

    Args:
        target: ``"spawn"``, a ``rerun+http://host:port/proxy`` URL, or an ``.rrd`` path
            (parent folders are created).
        application_id: rerun application id.
        recording_id: rerun recording id (default: a fresh one).
        memory_limit: memory limit of a spawned viewer (e.g. ``"2GB"`` or ``"25%"``).
        blueprint: default layout sent with the connection.

    Example:
        >>> import tempfile, os
        >>> path = os.path.join(tempfile.mkdtemp(), "run.rrd")
        >>> recording = open_recording(path)
        >>> recording.flush()
        >>> os.path.exists(path)
        True
    """
    kind = describe_target(target)
    recording = rr.RecordingStream(
        application_id,
        recording_id=recording_id,
        batcher_config=FILE_BATCHING if kind == "file" else None,
    )
    if kind == "spawn":
        recording.spawn(memory_limit=memory_limit, default_blueprint=blueprint)
    elif kind == "grpc":
        recording.connect_grpc(str(target), default_blueprint=blueprint)
    else:
        path = Path(target)
        path.parent.mkdir(parents=True, exist_ok=True)
        recording.save(path, default_blueprint=blueprint)
    logger.info("rerun recording -> %s", target)
    return recording


def is_live(target: str | Path) -> bool:
    """Whether ``target`` is a viewer (spawned or over gRPC) rather than an ``.rrd`` file.

    Example:
        >>> is_live("spawn"), is_live("runs/eval.rrd")
        (True, False)
    """
    return describe_target(target) != "file"


class LayoutSender:
    """Sends a recording's layout (blueprint): at once to a live viewer; to a file, the latest
    one at :meth:`flush`. Blueprints are built only when sent.

    Example:
        >>> sender = LayoutSender(rr.RecordingStream("doc"), live=False)
        >>> sender.send(lambda: rrb.Blueprint(rrb.TextLogView(origin="events")))
        >>> sender.pending
        True
        >>> sender.flush(); sender.pending
        False
    """

    def __init__(self, recording: rr.RecordingStream, live: bool) -> None:
        self.recording = recording
        self.live = live
        self._pending: Callable[[], rrb.Blueprint] | None = None
        self._latest: Callable[[], rrb.Blueprint] | None = None

    @property
    def pending(self) -> bool:
        """Whether a layout waits for :meth:`flush`."""
        return self._pending is not None

    def send(self, blueprint: Callable[[], rrb.Blueprint]) -> None:
        """Send the layout ``blueprint()`` builds (now if live, else at the next flush)."""
        if self.live:
            self.recording.send_blueprint(blueprint())
            self._latest = blueprint
        else:
            self._pending = blueprint

    def flush(self) -> None:
        """Send the layout that waits, if any."""
        blueprint, self._pending = self._pending, None
        if blueprint is not None:
            self.recording.send_blueprint(blueprint())
            self._latest = blueprint

    def latest(self) -> rrb.Blueprint | None:
        """The last layout sent (built anew), or None."""
        return None if self._latest is None else self._latest()


def layout_first(
    path: str | Path, blueprint: rrb.Blueprint | None, first: Sequence[str] = ()
) -> bool:
    """Rewrite the finished ``.rrd`` at ``path`` with ``blueprint`` as its default layout at the
    start, then the chunks of the entities under ``first`` (e.g. the summary), then the rest in
    their order: a viewer then lays the file out and shows those entities at once, however long
    the rest takes to read. Returns False (the file as it was) where this rerun-sdk cannot read
    a file back (before 0.32).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "run.rrd"
        >>> recording = open_recording(path)
        >>> recording.log("env/0/speed", rr.Scalars(1.0))
        >>> recording.log("summary/n", rr.Scalars(2.0))
        >>> recording.disconnect()
        >>> layout_first(path, rrb.Blueprint(rrb.TextLogView(origin="summary")), ["summary"])
        True
        >>> from rerun.experimental import RrdReader
        >>> [chunk.entity_path for chunk in RrdReader(path).stream()]
        ['/summary/n', '/__properties', '/env/0/speed']
    """
    try:
        from rerun.experimental import RrdReader, send_chunks
    except ImportError:
        logger.debug("rerun-sdk %s reads no file back: %s keeps its order", rr.__version__, path)
        return False
    path = Path(path)
    reader = RrdReader(path)
    (store,) = reader.recordings()
    chunks = list(reader.stream(store=store))
    prefixes = tuple(f"/{root}/" for root in first)
    early = [chunk for chunk in chunks if chunk.entity_path.startswith(prefixes)]
    late = [chunk for chunk in chunks if not chunk.entity_path.startswith(prefixes)]
    partial = path.with_name(f"{path.name}.partial")
    out = rr.RecordingStream(
        store.application_id, recording_id=store.recording_id, send_properties=False
    )
    out.save(partial, default_blueprint=blueprint)
    send_chunks([*early, *late], recording=out)
    out.flush()
    out.disconnect()
    os.replace(partial, path)
    return True
