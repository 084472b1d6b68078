"""Writes :class:`~oasis_torchrl.viz.records.StepRecord` s into a rerun recording.

Step ``tick`` (every logged reset or step is one tick) covers world frames ``4 * tick`` to
``4 * tick + 3``: action ``k`` and ground truth ``k`` sit on frame ``4 * tick + k`` (frame ``k``
is the world after action ``k``), the chunk's last image, reward, terms and depth on the last
frame. Scalars go through a :class:`~oasis_torchrl.viz.series.SeriesBuffer` (sent as columns,
at most a second late to a viewer, 30 s to a file). Each row keeps a little state (episode
number, step count, return, collision, its road map, a fixed-size path buffer and the episode's
actions), never frames. The top-down view is drawn in the car's frame at every step
(:mod:`oasis_torchrl.viz.topdown`); the road comes from ``scenes(prompt, seed)`` once per
episode.

Episodes are numbered in the order they start (rows in order at a shared reset: an evaluation's
batch ``b`` of ``n`` rows holds episodes ``b * n`` to ``b * n + n - 1``, its report's order),
unless the reset names them (the robot's: its dataset episode). An episode's end is one event,
with its cause and final figures, on the frame of its last logged data (the last frame of its
last step); a collision is also marked where it happened, on the speed and distance plots. The
end also makes an :class:`~oasis_torchrl.viz.summary.EpisodeOutcome` for the summary tab and
names the row's tab.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from oasis_torchrl.client.scenes import SceneLookup
from oasis_torchrl.protocol import CHUNK
from oasis_torchrl.viz.blueprint import RowsLayout
from oasis_torchrl.viz.images import depth_archetype, image_archetype
from oasis_torchrl.viz.options import LogOptions
from oasis_torchrl.viz.palette import Policy, series_style, signal_key
from oasis_torchrl.viz.paths import ENV_ROOT, RowPaths
from oasis_torchrl.viz.recording import LayoutSender
from oasis_torchrl.viz.records import StepRecord
from oasis_torchrl.viz.series import (
    FILE_DELAY_S,
    FILE_MAX_VALUES,
    LIVE_DELAY_S,
    LIVE_MAX_VALUES,
    SeriesBuffer,
)
from oasis_torchrl.viz.summary import EpisodeOutcome, EpisodeSummary
from oasis_torchrl.viz.timelines import set_frame
from oasis_torchrl.viz.titles import EpisodeMark, RowEpisodes
from oasis_torchrl.viz.topdown import (
    CAR_COLOR,
    CAR_SIZE,
    CRASHED_COLOR,
    DRAW_ORDER,
    PATH_COLOR,
    PATH_EVERY,
    PATH_RADIUS,
    ROAD_COLOR,
    SCALE_COLOR,
    SCALE_RADIUS,
    Capsules,
    RoadMap,
    Trail,
    Window,
    car_capsule,
    car_frame,
    scale_bar,
)

logger = logging.getLogger(__name__)

ACTION_NAMES = ("throttle", "steering")
_LAST = CHUNK - 1
LEVELS = {
    "collision": "ERROR",
    "likely collision": "WARN",
    "terminated": "WARN",
    "time limit": "INFO",
    "ended": "INFO",
}
"""Event level of each way an episode ends."""


@dataclass
class _RowState:
    """What the writer remembers about one row between steps."""

    trail: Trail
    episode: int = -1
    episodes: RowEpisodes = field(default_factory=RowEpisodes)
    step: int = 0
    episode_return: float = 0.0
    collided: bool = False
    collision: str = ""
    start_frame: int = 0
    prompt: str | None = None
    seed: int | None = None
    road: RoadMap | None = None
    actions: list[np.ndarray] = field(default_factory=list)


class RecordWriter:
    """Logs step records of env rows under ``<root>/<row>`` (``env`` by default); sends the
    default blueprint as rows, cameras, plots, the top-down view and the summary appear.

    ``scenes`` (settable) is where the top-down view's road and obstacles come from, e.g. a
    :class:`~oasis_torchrl.client.scenes.SceneSource`; None draws the car and its path only.
    Each episode's end is one event that names its cause and final figures, and an outcome in
    ``summary`` (the summary tab); ``send_layout`` replaces the default blueprint (a side-by-side
    recording lays several writers out together), which goes to a ``live`` viewer as it
    changes, else at :meth:`flush`. ``policy`` names and colours the signals that policies side
    by side share a plot for; ``name`` (whose episodes these are: the policy's, dataset's or
    robot's) titles every panel of the layout.

    Example:
        >>> writer = RecordWriter(rr.RecordingStream("doc"), LogOptions(background=False))
        >>> record = StepRecord(rows=[0], start=True, prompts=["rural road"], seeds=[1])
        >>> writer.write(record, tick=0)  # logs "episode 0 starts: 'rural road', seed 1"
    """

    def __init__(
        self,
        recording: rr.RecordingStream,
        options: LogOptions,
        scenes: SceneLookup | None = None,
        *,
        root: str = ENV_ROOT,
        summary: EpisodeSummary | None = None,
        send_layout: Callable[[RowsLayout], None] | None = None,
        live: bool = True,
        policy: Policy | None = None,
        name: str = "",
    ) -> None:
        self.recording = recording
        self.name = name
        self.options = options
        self.scenes = scenes
        self.root = root
        self.summary = summary if summary is not None else EpisodeSummary(recording)
        self._layouts = LayoutSender(recording, live)
        self._send_layout = send_layout or self._send_default_blueprint
        style = functools.partial(series_style, policy=policy)
        delay, values = (LIVE_DELAY_S, LIVE_MAX_VALUES) if live else (FILE_DELAY_S, FILE_MAX_VALUES)
        self._series = SeriesBuffer(
            recording, options.fps, style=style, max_delay_s=delay, max_values=values
        )
        self._rows: dict[int, _RowState] = {}
        self._next_episode = 0
        self._cameras: list[str] = []
        self._depth_cameras: list[str] = []
        self._signals: set[str] = set()
        self._topdown = False
        self._ended = False
        self._layout: RowsLayout | None = None

    def write(self, record: StepRecord, tick: int) -> None:
        """Log ``record`` as step ``tick`` (frames ``4 * tick`` to ``4 * tick + 3``)."""
        first = tick * CHUNK
        self._note_contents(record)
        for i, row in enumerate(record.rows):
            state = self._rows.setdefault(row, _RowState(Trail(self.options.trail_frames)))
            paths = RowPaths(self.root, row)
            if record.start or state.episode < 0:
                self._start_episode(paths, state, record, i, first)
            else:
                state.step += 1
            self._write_series(paths, record, i, first)
            collision_frame = self._write_frames(paths, state, record, i, first)
            self._at(first + _LAST)
            self._write_depth(paths, record, i)
            self._write_topdown(paths, state, record, i)
            if not record.start:  # a reset observation has no reward (its terms are zeros)
                if record.actions is not None:
                    state.actions.append(record.actions[i])
                self._write_rewards(paths, state, record, i, first + _LAST)
                self._write_episode_end(paths, state, record, i, collision_frame, first)
        self._update_blueprint()

    def flush(self) -> None:
        """Send the buffered time series and a layout that waits (never while a write runs on
        another thread)."""
        self._series.flush()
        self._layouts.flush()

    # -- helpers -----------------------------------------------------------------------------

    def _at(self, frame: int) -> None:
        set_frame(self.recording, frame, self.options.fps)

    def _event(self, paths: RowPaths, text: str, level: str) -> None:
        self.recording.log(paths.events, rr.TextLog(text, level=level))

    def _add_series(self, path: str, frames: np.ndarray, values: np.ndarray) -> None:
        self._signals.add(signal_key(path))
        self._series.add(path, frames, values)

    # -- blueprint ---------------------------------------------------------------------------

    def _note_contents(self, record: StepRecord) -> None:
        self._cameras += [c for c in record.images if c not in self._cameras]
        self._depth_cameras += [c for c in record.depth if c not in self._depth_cameras]
        self._topdown |= self.options.topdown and {"x", "y"} <= set(record.truth)

    def _update_blueprint(self) -> None:
        layout = RowsLayout(
            self.root,
            tuple(sorted(self._rows)),
            tuple(self._cameras),
            tuple(self._depth_cameras),
            self.options.topdown_window if self._topdown else None,
            frozenset(self._signals),
            self._ended,
            tuple(self._rows[row].episodes for row in sorted(self._rows)),
            self.name,
        )
        if layout != self._layout:
            self._layout = layout
            self._send_layout(layout)

    def latest_layout(self) -> rrb.Blueprint | None:
        """The last default layout sent (None: none, or another sends the layout)."""
        return self._layouts.latest()

    def _send_default_blueprint(self, layout: RowsLayout) -> None:
        self._layouts.send(lambda: layout.blueprint(self.options.fps))

    # -- episodes ----------------------------------------------------------------------------

    def _start_episode(
        self, paths: RowPaths, state: _RowState, record: StepRecord, i: int, first: int
    ) -> None:
        state.episode = record.episodes[i] if record.episodes else self._next_episode
        self._next_episode = max(self._next_episode, state.episode + 1)
        state.episodes = state.episodes.add(EpisodeMark(state.episode))
        state.step = 0
        state.episode_return = 0.0
        state.collided = False
        state.collision = ""
        state.start_frame = first
        state.actions.clear()
        state.trail.clear()
        state.prompt = record.prompts[i] if record.prompts else None
        state.seed = int(record.seeds[i]) if record.seeds else None
        has_poses = {"x", "y"} <= set(record.truth)
        state.road = self._road(state.prompt, state.seed) if has_poses else None
        self._at(first)
        if state.prompt is None:
            self._event(paths, f"episode {state.episode} starts (new clip)", "INFO")
        else:
            self._event(
                paths,
                f"episode {state.episode} starts: {state.prompt!r}, seed {state.seed}",
                "INFO",
            )
        if self._topdown:
            empty = rr.LineStrips2D([])
            for layer in ("road", "lanes", "obstacles"):
                self.recording.log(paths.topdown(layer), empty)

    def _road(self, prompt: str | None, seed: int | None) -> RoadMap | None:
        source = self.scenes
        if not self.options.topdown or source is None or prompt is None or seed is None:
            return None
        try:
            scene = source(prompt, seed)
        except Exception as error:  # a missing scene must not stop the logging of a rollout
            logger.warning("no top-down road for %r seed %s: %s", prompt, seed, error)
            return None
        return None if scene is None else RoadMap.from_scene(scene)

    def _write_episode_end(
        self,
        paths: RowPaths,
        state: _RowState,
        record: StepRecord,
        i: int,
        collision_frame: int | None,
        first: int,
    ) -> None:
        """One event for the episode's end, on its last frame (nothing of it is logged later),
        with its cause and final figures; a collision is marked on the plots at its own frame,
        and is an event of its own when the episode goes on."""
        if collision_frame is not None:
            self._mark_collision(paths, record, i, collision_frame)
        cause = self._end_cause(state, record, i)
        if cause is None:
            if collision_frame is not None:
                self._at(collision_frame)
                self._event(paths, f"collision at step {state.step}: {state.collision}", "ERROR")
            return
        distance = record.truth.get("distance")
        outcome = EpisodeOutcome(
            self.root,
            paths.row,
            state.episode,
            state.prompt,
            state.seed,
            state.start_frame,
            first + _LAST,
            state.step,
            *cause,
            math.nan if distance is None else float(distance[i, -1]),
            state.episode_return,
            np.concatenate(state.actions) if state.actions else np.zeros((0, 2)),
        )
        self._at(outcome.end_frame)
        self._event(
            paths,
            f"episode {state.episode} ends: {outcome.outcome()} after {outcome.figures()}",
            LEVELS[outcome.cause],
        )
        state.episodes = state.episodes.ended(EpisodeMark(state.episode, cause[0], state.step))
        self._ended = True
        self.summary.add(outcome)

    def _mark_collision(self, paths: RowPaths, record: StepRecord, i: int, frame: int) -> None:
        """The speed and the distance ahead at a collision's frame, drawn as a cross on their
        plots (a distance past the sensor's range counts as 0: the car is touching something)."""
        k = frame % CHUNK
        for name in ("speed", "obstacle_distance"):
            values = record.truth.get(name)
            if values is not None and name in self.options.truth_series:
                value = float(values[i, k])
                value = value if math.isfinite(value) else 0.0
                self._add_series(paths.scalar("collision", name), np.array([frame]), [value])

    @staticmethod
    def _end_cause(state: _RowState, record: StepRecord, i: int) -> tuple[str, str] | None:
        """``(cause, detail)`` if the row's episode ends with this step, else None."""
        terminated = record.terminated is not None and bool(record.terminated[i])
        truncated = record.truncated is not None and bool(record.truncated[i])
        done = record.done is not None and bool(record.done[i])
        if not (terminated or truncated or done):
            return None
        if state.collided:
            return "collision", state.collision
        risk = record.terms.get("collision_risk")
        if terminated and risk is not None and risk[i] >= 1.0:
            return "likely collision", f"depth risk {float(risk[i]):.2f}"
        if terminated:
            return "terminated", ""
        return ("time limit", "") if truncated else ("ended", "")

    # -- per-frame and per-step values -------------------------------------------------------

    def _write_series(self, paths: RowPaths, record: StepRecord, i: int, first: int) -> None:
        """Per-frame series: the 4 actions of the chunk and the chosen ground-truth fields."""
        frames = np.arange(first, first + CHUNK)
        if record.actions is not None:
            for column, name in enumerate(ACTION_NAMES):
                self._add_series(paths.scalar("action", name), frames, record.actions[i, :, column])
        for name in self.options.truth_series:
            if name in record.truth:
                self._add_series(paths.scalar("truth", name), frames, record.truth[name][i])

    def _write_frames(
        self, paths: RowPaths, state: _RowState, record: StepRecord, i: int, first: int
    ) -> int | None:
        """Per frame of the chunk: the camera images. Returns the frame of the episode's first
        collision if it is in this chunk (noted in ``state``)."""
        quality = self.options.jpeg_quality
        collided = record.truth.get("collided")
        off_road = record.truth.get("off_road")
        collision_frame = None
        for k in range(CHUNK):
            self._at(first + k)
            if collided is not None and collided[i, k] > 0.5 and not state.collided:
                state.collided = True
                left_road = off_road is not None and off_road[i, k] > 0.5
                state.collision = "left the road" if left_road else "hit an obstacle"
                collision_frame = first + k
            for camera, frames in record.images.items():
                every = frames.shape[1] == CHUNK and self.options.all_frames
                if every or k == _LAST:
                    image = frames[i, k if every else -1]
                    self.recording.log(paths.camera(camera), image_archetype(image, quality))
        return collision_frame

    def _write_rewards(
        self, paths: RowPaths, state: _RowState, record: StepRecord, i: int, last: int
    ) -> None:
        frame = np.array([last])
        if record.reward is not None:
            state.episode_return += float(record.reward[i])
            self._add_series(paths.scalar("reward", "total"), frame, record.reward[i : i + 1])
        for name, values in record.terms.items():
            self._add_series(paths.scalar("reward", name), frame, values[i : i + 1])

    def _write_depth(self, paths: RowPaths, record: StepRecord, i: int) -> None:
        for camera, depth in record.depth.items():
            self.recording.log(paths.depth(camera), depth_archetype(depth[i]))

    # -- top-down ----------------------------------------------------------------------------

    def _write_topdown(self, paths: RowPaths, state: _RowState, record: StepRecord, i: int) -> None:
        truth = record.truth
        if not (self.options.topdown and "x" in truth and "y" in truth):
            return
        positions = np.stack([truth["x"][i], truth["y"][i]], axis=-1).astype(np.float64)
        state.trail.extend(positions)
        car = positions[-1]
        if not np.isfinite(car).all():
            return
        heading = float(truth["heading"][i, -1]) if "heading" in truth else 0.0
        window = self.options.topdown_window
        if state.episodes.count == 1 and state.step == 0:
            self._log_scale(paths, window)
        if state.road is not None:
            self._write_map(paths, state.road, car, heading)
        path = car_frame(state.trail.points(), car, heading)
        outside = np.flatnonzero(~window.contains(path, margin=PATH_RADIUS))
        path = path[outside[-1] + 1 :] if len(outside) else path
        path = path[(len(path) - 1) % PATH_EVERY :: PATH_EVERY]  # ends at the car
        self._log_layer(paths, "path", [path], [PATH_RADIUS], [PATH_COLOR])
        size = state.road.car_size if state.road is not None else CAR_SIZE
        self._log_capsules(
            paths, "car", car_capsule(size, CRASHED_COLOR if state.collided else CAR_COLOR)
        )

    def _write_map(self, paths: RowPaths, road: RoadMap, car: np.ndarray, heading: float) -> None:
        view = road.view(car, heading, self.options.topdown_window)
        self._log_layer(paths, "road", view.road, [view.road_radius] * len(view.road), [ROAD_COLOR])
        self._log_layer(paths, "lanes", view.markings, view.marking_radii, view.marking_colors)
        self._log_capsules(paths, "obstacles", view.obstacles)

    def _log_scale(self, paths: RowPaths, window: Window) -> None:
        strip, metres = scale_bar(window)
        self.recording.log(
            paths.topdown("scale"),
            rr.LineStrips2D(
                [strip],
                radii=[SCALE_RADIUS],
                colors=[SCALE_COLOR],
                labels=[f"{metres} m"],
                draw_order=DRAW_ORDER["scale"],
            ),
            static=True,
        )

    def _log_capsules(self, paths: RowPaths, layer: str, capsules: Capsules) -> None:
        self._log_layer(paths, layer, list(capsules.ends), capsules.radii, capsules.colors)

    def _log_layer(
        self,
        paths: RowPaths,
        layer: str,
        strips: list[np.ndarray],
        radii: list[float] | np.ndarray,
        colors: list,
    ) -> None:
        """One top-down layer: strips in view coordinates, radii in metres (filled widths)."""
        self.recording.log(
            paths.topdown(layer),
            rr.LineStrips2D(strips, radii=radii, colors=colors, draw_order=DRAW_ORDER[layer]),
        )
