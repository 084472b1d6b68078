"""Policies side by side: two or more policies' episodes on the same seeds in one recording.

Each policy logs its rows under a root of its own (``<policy>/<row>/...``, the name made an
entity name) through its own :class:`~oasis_torchrl.viz.RolloutLogger` sharing one recording
stream; their episodes start at the same ticks (:meth:`~oasis_torchrl.viz.RolloutLogger.align`),
so one timeline shows them together. The layout has the summary tab (every episode's outcome and
distance per policy) and one tab per env row, named after its episode and each policy's
outcome: a line per policy with its cameras (the same cameras in every line), top-down view and
events, every panel titled with its policy; below them the speed and the distance to the
obstacle ahead of every policy on shared axes (a line each in the policy's colour, a cross at a
collision), each policy's actions and the ``divergence/<row>`` events: the first step of each
episode where a policy's actions differ from the first policy's by more than a threshold.

``oasis-torchrl view A.rrd B.rrd`` (:func:`align_recordings`) lays out saved recordings the same
way, copying each under its own root (needs rerun-sdk 0.32 or newer, whose chunk reader this
uses).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from oasis_torchrl.client.scenes import SceneLookup
from oasis_torchrl.protocol import CHUNK
from oasis_torchrl.viz.blueprint import (
    RowsLayout,
    camera_views,
    events_view,
    summary_layout,
    time_panel,
    topdown_view,
)
from oasis_torchrl.viz.logger import RolloutLogger
from oasis_torchrl.viz.options import LogOptions
from oasis_torchrl.viz.palette import COMPARED, SHARED_PLOTS, Plot, Policy, series_style
from oasis_torchrl.viz.paths import ENV_ROOT, FRAME_TIMELINE, RowPaths
from oasis_torchrl.viz.recording import LayoutSender, is_live, layout_first, open_recording
from oasis_torchrl.viz.summary import SUMMARY_ROOT, TABLE, EpisodeSummary, chart_path
from oasis_torchrl.viz.timelines import set_frame
from oasis_torchrl.viz.titles import episodes_of, panel_title, tab_title
from oasis_torchrl.viz.topdown import DEFAULT_WINDOW
from oasis_torchrl.viz.writer import ACTION_NAMES

logger = logging.getLogger(__name__)

DIVERGENCE_ROOT = "divergence"
"""Root of the divergence events (``divergence/<row>``)."""
DEFAULT_THRESHOLD = 0.25
"""Actions further apart than this (throttle or steering) mark a divergence."""
SIGNAL_GROUPS = ("action", "reward", "truth", "collision", "state")


def policy_roots(names: Sequence[str]) -> dict[str, str]:
    """Each policy name made a distinct entity root (letters, digits, ``_`` and ``-``).

    Example:
        >>> policy_roots(["autopilot", "bc+ppo", "outputs/bc/policy"])
        {'autopilot': 'autopilot', 'bc+ppo': 'bc_ppo', 'outputs/bc/policy': 'outputs_bc_policy'}
        >>> policy_roots(["a.b", "a b"])
        {'a.b': 'a_b', 'a b': 'a_b_2'}
    """
    if len(set(names)) != len(names) or len(names) < 2:
        raise ValueError(f"side by side needs two or more distinct policy names, got {names}")
    roots: dict[str, str] = {}
    for name in names:
        root = re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_") or "policy"
        if root in (SUMMARY_ROOT, DIVERGENCE_ROOT):
            root += "_policy"
        candidate, count = root, 1
        while candidate in roots.values():
            count += 1
            candidate = f"{root}_{count}"
        roots[name] = candidate
    return roots


def first_divergence(a: np.ndarray, b: np.ndarray, threshold: float) -> tuple[int, float] | None:
    """The first index where two action series ``[T, ...]`` differ by more than ``threshold``
    (largest component), and that difference; None if they never do (over their common length).

    Example:
        >>> a = np.zeros((5, 2)); b = a.copy(); b[3, 1] = 0.5
        >>> first_divergence(a, b, 0.25)
        (3, 0.5)
        >>> first_divergence(a, b, 0.6) is None
        True
    """
    steps = min(len(a), len(b))
    gaps = np.abs(a[:steps] - b[:steps]).reshape(steps, -1).max(axis=1, initial=0.0)
    over = np.flatnonzero(np.nan_to_num(gaps) > threshold)
    return None if not len(over) else (int(over[0]), float(gaps[over[0]]))


def side_by_side_blueprint(
    layouts: Sequence[RowsLayout], fps: float | None = None
) -> rrb.Blueprint:
    """The summary tab and a tab per env row, a line per policy (``layouts``, one per root).

    Example:
        >>> layouts = [RowsLayout(root, (0,), ("front",), (), None, frozenset(), True, owner=root)
        ...            for root in ("autopilot", "bc")]
        >>> type(side_by_side_blueprint(layouts)).__name__
        'Blueprint'
    """
    rows = sorted({row for layout in layouts for row in layout.rows})
    cameras = aligned_cameras(layouts)
    roots, owners = [layout.root for layout in layouts], [layout.owner for layout in layouts]
    tabs = [summary_layout(roots, owners)]
    tabs += [_row_tab(layouts, row, cameras) for row in rows]
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), time_panel(fps))


def aligned_cameras(layouts: Sequence[RowsLayout]) -> list[str]:
    """Every policy's cameras, in the first policy's order and then as they come: each line of
    a row shows the same ones, so the same camera is in the same column.

    Example:
        >>> layouts = [RowsLayout("a", (0,), ("left", "front"), (), None, frozenset(), True),
        ...            RowsLayout("b", (0,), ("front", "front_crop"), (), None, frozenset(), True)]
        >>> aligned_cameras(layouts)
        ['left', 'front', 'front_crop']
    """
    cameras: list[str] = []
    for layout in layouts:
        cameras += [camera for camera in layout.cameras if camera not in cameras]
    return cameras


def _policy_line(layout: RowsLayout, row: int, cameras: Sequence[str]) -> rrb.Horizontal:
    paths, owner = RowPaths(layout.root, row), layout.owner
    views = [camera_views(paths, cameras, owner)]
    if layout.topdown is not None:
        views.append(topdown_view(paths, layout.topdown, owner))
    views.append(events_view(paths, owner))
    shares = [3, 1, 1] if layout.topdown is not None else [3, 1]
    return rrb.Horizontal(*views, column_shares=shares, name=layout.root)


def _shared_plot(layouts: Sequence[RowsLayout], row: int, plot: Plot) -> rrb.TimeSeriesView:
    """One plot with every policy's lines of the row (each in its policy's colour)."""
    contents = [
        f"+ /{RowPaths(layout.root, row).base}/{key}" for layout in layouts for key in plot.include
    ]
    return rrb.TimeSeriesView(origin="/", contents=contents, name=plot.title)


def _row_tab(layouts: Sequence[RowsLayout], row: int, cameras: Sequence[str]) -> rrb.Vertical:
    lines = [_policy_line(layout, row, cameras) for layout in layouts]
    signals = {key for layout in layouts for key in layout.signals}
    shared = [
        _shared_plot(layouts, row, plot)
        for plot in SHARED_PLOTS
        if any(plot.shows(key) for key in signals)
    ]
    actions = [
        rrb.TimeSeriesView(
            origin=RowPaths(layout.root, row).base,
            contents=["+ $origin/action/**"],
            name=panel_title(layout.owner, "actions (-1 to 1)"),
        )
        for layout in layouts
    ]
    divergence = rrb.TextLogView(origin=f"{DIVERGENCE_ROOT}/{row}", name="divergence")
    title = tab_title(row, {layout.root: layout.row_episodes(row) for layout in layouts})
    bottom = [rrb.Horizontal(*shared)] if shared else []
    bottom.append(rrb.Horizontal(*actions, divergence))
    shares = [3] * len(lines) + [2] * len(bottom)
    return rrb.Vertical(*lines, *bottom, row_shares=shares, name=title)


class SideBySide:
    """Records two or more policies' episodes into one recording, side by side.

    Args:
        target: an ``.rrd`` path, ``"spawn"`` or a viewer URL.
        names: the policies, in column order; the first is the one the others are compared
            with for divergences.
        threshold: actions further apart than this mark a divergence.
        options: what each policy's logger logs.

    Example:
        >>> import tempfile, os
        >>> recording = SideBySide(os.path.join(tempfile.mkdtemp(), "pair.rrd"), ["a", "b"])
        >>> type(recording.logger("b")).__name__
        'RolloutLogger'
        >>> recording.close()
    """

    def __init__(
        self,
        target: str | Path,
        names: Sequence[str],
        *,
        threshold: float = DEFAULT_THRESHOLD,
        options: LogOptions | None = None,
    ) -> None:
        self.roots = policy_roots(list(names))
        self.threshold = threshold
        self.options = options if options is not None else LogOptions()
        self.recording = open_recording(target)
        self.live = is_live(target)
        self._file = None if self.live else Path(target)
        self.summary = EpisodeSummary(self.recording, tuple(self.roots.values()))
        self._layouts: dict[str, RowsLayout] = {}
        self._sender = LayoutSender(self.recording, self.live)

    def logger(self, name: str, scenes: SceneLookup | None = None) -> RolloutLogger:
        """A logger for policy ``name``'s episodes (close it when its evaluation is done)."""
        root = self.roots[name]
        return RolloutLogger(
            self.recording,
            self.options,
            scenes=scenes,
            root=root,
            summary=self.summary,
            send_layout=self._send_layout,
            live=self.live,
            policy=Policy.at(root, list(self.roots.values()).index(root)),
            name=root,
        )

    def close(self) -> None:
        """Mark the divergences, send the final layout, then finish the recording."""
        try:
            self._log_divergences()
            self._sender.flush()
        finally:
            self.recording.flush()
            self.recording.disconnect()
        if self._file is not None:
            layout_first(self._file, self._sender.latest(), [SUMMARY_ROOT])

    def _send_layout(self, layout: RowsLayout) -> None:
        self._layouts[layout.root] = layout
        ordered = [self._layouts[root] for root in self.roots.values() if root in self._layouts]
        self._sender.send(lambda: side_by_side_blueprint(ordered, self.options.fps))

    def _log_divergences(self) -> None:
        reference, *others = self.roots.values()
        outcomes = {(o.root, o.scene()): o for o in self.summary.outcomes}
        for scene in self.summary.scenes():
            first = outcomes.get((reference, scene))
            for root in others:
                other = outcomes.get((root, scene))
                if first is None or other is None:
                    continue
                divergence = first_divergence(first.actions, other.actions, self.threshold)
                if divergence is not None:
                    index, gap = (
                        divergence  # a frame of the episode's steps (the reset is one tick)
                    )
                    step = index // CHUNK + 1
                    text = f"step {step}: {root} diverges from {reference} (by {gap:.2f})"
                    frame = other.start_frame + CHUNK + index
                    _log_event(self.recording, scene[0], frame, text, self.options.fps)


def _log_event(recording: rr.RecordingStream, row: int, frame: int, text: str, fps: float) -> None:
    set_frame(recording, frame, fps)
    recording.log(f"{DIVERGENCE_ROOT}/{row}", rr.TextLog(text, level="WARN"))


def align_recordings(
    paths: Sequence[str | Path],
    target: str | Path,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    fps: float | None = None,
) -> dict[str, str]:
    """Copy saved recordings (``env/<row>`` each) into one, each under a root named after its
    file, laid out side by side on their shared ``frame`` timeline, with the first frame of each
    row where their actions diverge marked and their summary tables one under the other;
    returns file -> root.

    Example:
        >>> align_recordings(["a.rrd", "b.rrd"], "pair.rrd")  # doctest: +SKIP
        {'a.rrd': 'a', 'b.rrd': 'b'}
    """
    try:
        from rerun.experimental import RrdReader, send_chunks
    except ImportError:
        raise ValueError(
            f"aligning recordings needs rerun-sdk 0.32 or newer (installed: {rr.__version__})"
        ) from None
    names = [str(path) for path in paths]
    roots = dict(zip(names, policy_roots([Path(p).stem for p in names]).values(), strict=True))
    fps = fps if fps is not None else LogOptions().fps
    recording = open_recording(target)
    layouts, actions = [], {}
    try:
        tables = []
        for index, (name, root) in enumerate(roots.items()):
            chunks = list(RrdReader(name).stream())
            rerooted = [_rerooted(chunk, root) for chunk in chunks if _kept(chunk)]
            send_chunks(rerooted, recording=recording)
            layouts.append(_layout_of(root, chunks))
            _restyle(recording, layouts[-1], Policy.at(root, index))
            actions[root] = _actions_by_frame(chunks)
            tables.append(f"## {root} ({name})\n\n{_table_of(chunks)}")
        document = rr.TextDocument("\n\n".join(tables), media_type="text/markdown")
        recording.log(TABLE, document, static=True)
        recording.send_blueprint(side_by_side_blueprint(layouts, fps))
        _log_frame_divergences(recording, actions, threshold, fps)
    finally:
        recording.flush()
        recording.disconnect()
    return roots


def _restyle(recording: rr.RecordingStream, layout: RowsLayout, policy: Policy) -> None:
    """Give a copied recording's shared-plot signals its policy's name and colour."""
    for row in layout.rows:
        for key in sorted(layout.signals & COMPARED):
            path = f"{RowPaths(layout.root, row).base}/{key}"
            recording.log(path, series_style(path, policy), static=True)


def _kept(chunk: object) -> bool:
    path = chunk.entity_path
    return path.startswith(f"/{ENV_ROOT}/") or path == f"/{chart_path(ENV_ROOT)}"


def _table_of(chunks: Sequence[object]) -> str:
    """The summary table a recording holds (empty if none of its episodes ended)."""
    texts = [
        value[0]
        for chunk in chunks
        if chunk.entity_path == f"/{TABLE}"
        for value in chunk.to_record_batch().column("TextDocument:text").to_pylist()
        if value
    ]
    return texts[-1] if texts else "(no episode ended)"


def _rerooted(chunk: object, root: str) -> object:
    path = chunk.entity_path
    if path.startswith(f"/{SUMMARY_ROOT}/"):
        return chunk.with_entity_path(f"/{SUMMARY_ROOT}/{root}")
    return chunk.with_entity_path(f"/{root}/" + path.removeprefix(f"/{ENV_ROOT}/"))


def _layout_of(root: str, chunks: Sequence[object]) -> RowsLayout:
    """The layout of one copied recording, from its entity paths and its rows' events."""
    rows, cameras, signals, topdown = set(), [], set(), False
    for path in (chunk.entity_path for chunk in chunks):
        parts = path.strip("/").split("/")
        if len(parts) < 3 or parts[0] != ENV_ROOT or not parts[1].isdigit():
            continue
        rows.add(int(parts[1]))
        if parts[2] == "camera" and len(parts) > 3 and parts[3] not in cameras:
            cameras.append(parts[3])
        if parts[2] in SIGNAL_GROUPS and len(parts) == 4:
            signals.add(f"{parts[2]}/{parts[3]}")
        topdown |= parts[2] == "topdown"
    window = DEFAULT_WINDOW if topdown else None
    ordered = tuple(sorted(rows))
    episodes = tuple(episodes_of(_events_of(chunks, row)) for row in ordered)
    return RowsLayout(
        root, ordered, tuple(cameras), (), window, frozenset(signals), True, episodes, root
    )


def _events_of(chunks: Sequence[object], row: int) -> list[str]:
    """A row's event texts, in frame order."""
    events = []
    for chunk in chunks:
        if chunk.entity_path != f"/{RowPaths(ENV_ROOT, row).events}":
            continue
        batch = chunk.to_record_batch()
        texts = batch.column("TextLog:text").to_pylist()
        events += zip(batch.column(FRAME_TIMELINE).to_pylist(), texts, strict=True)
    return [text[0] for _, text in sorted(events, key=lambda pair: pair[0]) if text]


def _actions_by_frame(chunks: Sequence[object]) -> dict[int, dict[int, np.ndarray]]:
    """Row -> frame -> ``[throttle, steering]`` (NaN where missing) of a recording's chunks."""
    by_row: dict[int, dict[int, np.ndarray]] = {}
    for chunk in chunks:
        parts = chunk.entity_path.strip("/").split("/")
        if len(parts) != 4 or parts[0] != ENV_ROOT or parts[2] != "action":
            continue
        batch = chunk.to_record_batch()
        if parts[3] not in ACTION_NAMES or FRAME_TIMELINE not in batch.schema.names:
            continue
        column = ACTION_NAMES.index(parts[3])
        frames = batch.column(FRAME_TIMELINE).to_pylist()
        values = batch.column("Scalars:scalars").to_pylist()
        row = by_row.setdefault(int(parts[1]), {})
        for frame, value in zip(frames, values, strict=True):
            action = row.setdefault(frame, np.full(2, np.nan))
            action[column] = value[0] if value else np.nan
    return by_row


def _log_frame_divergences(
    recording: rr.RecordingStream,
    actions: dict[str, dict[int, dict[int, np.ndarray]]],
    threshold: float,
    fps: float,
) -> None:
    """Per row, the first frame where each recording's actions leave the first's."""
    reference, *others = actions
    for root in others:
        for row, frames in actions[root].items():
            base = actions[reference].get(row, {})
            shared = sorted(set(frames) & set(base))
            divergence = first_divergence(
                np.array([base[f] for f in shared]),
                np.array([frames[f] for f in shared]),
                threshold,
            )
            if divergence is not None:
                index, gap = divergence
                text = f"frame {shared[index]}: {root} diverges from {reference} (by {gap:.2f})"
                _log_event(recording, row, shared[index], text, fps)
