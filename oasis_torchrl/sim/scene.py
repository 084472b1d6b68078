"""Procedural driving scenes: a text prompt and a seed give a whole, deterministic world.

The prompt sets the scene's style (:mod:`oasis_torchrl.sim.style`: layout, lighting and
weather). Everything else (lane count, road curves, obstacles, roadside) is drawn from a
numpy Generator seeded with a SHA-256 of prompt and seed: the same prompt and seed give the
same world.

World frame: metres, x east, y north, headings counter-clockwise from +x. The road centreline is
``y = f(x)`` tabulated every :data:`ROAD_STEP` metres; road coordinates are ``s`` (arc length
along the centreline, 0 at the start) and ``d`` (lateral offset, + is left). Lane 0 is the
rightmost lane; the car starts in it, at rest, at ``s = 0``.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.sim.style import LAYOUT_SPECS, LayoutSpec, Style, parse_style

logger = logging.getLogger(__name__)

OBSTACLE_KINDS = ("car", "barrier", "pedestrian")
ROADSIDE_KINDS = ("building", "trees", "rail")

#: Spacing of the centreline lookup table, metres of x.
ROAD_STEP = 0.25
#: The table spans x from ROAD_START_X to ROAD_END_X (arc length is longer on curves).
ROAD_START_X = -150.0
ROAD_END_X = 6000.0
#: Nothing stands on the road surface closer than this to the start.
CLEAR_START = 45.0

#: (length along heading, width across, height) of each obstacle kind, metres.
OBSTACLE_SIZES = {
    "car": (4.4, 1.8, 1.5),
    "barrier": (0.5, 2.4, 1.0),
    "pedestrian": (0.5, 0.5, 1.75),
}
#: Colour variants per obstacle kind (cars and pedestrians' clothes have several).
OBSTACLE_VARIANTS = {"car": 4, "barrier": 1, "pedestrian": 4}
#: Colour variants per roadside kind.
ROADSIDE_VARIANTS = {"building": 3, "trees": 2, "rail": 1}


class Road:
    """The centreline ``y = f(x)`` as a dense lookup table, and road-coordinate conversions.

    Args:
        headings: Road heading (radians) at ``x0, x0 + step, ...``; ``|heading| < pi/2``.
        x0: x of the first sample.
        step: Sample spacing in x, metres.

    Example:
        >>> road = Road(np.zeros(400), x0=-50.0, step=0.25)
        >>> s, d = road.locate(np.array([10.0]), np.array([2.0]))
        >>> float(s[0]), float(d[0])
        (10.0, 2.0)
    """

    def __init__(self, headings: np.ndarray, x0: float, step: float = ROAD_STEP) -> None:
        headings = np.asarray(headings, dtype=np.float64)
        self.x0 = float(x0)
        self.step = float(step)
        self.x = self.x0 + self.step * np.arange(headings.size)
        self.heading = headings
        self.y = self._integrate(np.tan(headings))
        self.s = self._integrate(1.0 / np.cos(headings))
        self.curvature = np.gradient(headings, self.s)
        columns = np.stack([self.y, np.cos(headings), np.sin(headings), self.s])
        # The four columns, then their forward differences: one gather serves the linear
        # interpolation of all four.
        self._table = np.concatenate([columns, np.diff(columns, append=columns[:, -1:])])

    def _integrate(self, derivative: np.ndarray) -> np.ndarray:
        """Trapezoidal integral of ``derivative`` over x, zero at x = 0."""
        steps = (derivative[1:] + derivative[:-1]) * (self.step / 2)
        total = np.concatenate(([0.0], np.cumsum(steps)))
        return total - np.interp(0.0, self.x, total)

    @property
    def length(self) -> float:
        """Arc length from the start (s = 0) to the end of the table, metres."""
        return float(self.s[-1])

    def _lookup(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """Interpolated ``(y, cos, sin, s)`` of the centreline at ``x``, each shaped like ``x``."""
        position = (x - self.x0) * (1.0 / self.step)
        index = np.clip(position.astype(np.int64), 0, self.x.size - 2)
        fraction = position - index
        gathered = self._table.take(index, axis=1)
        return tuple(gathered[:4] + fraction * gathered[4:])

    def locate(
        self, x: np.ndarray, y: np.ndarray, iterations: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """Road coordinates ``(s, d)`` of world points (vectorised).

        Projects onto the tangent at the sample below each point; each extra iteration moves
        that sample to the previous foot point (1 is accurate to centimetres within a few lanes
        on these curves; 2 for tens of metres).
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        foot = x
        for iteration in range(iterations):
            centre_y, cos, sin, s = self._lookup(foot)
            dx, dy = x - foot, y - centre_y
            along = cos * dx + sin * dy
            if iteration + 1 < iterations:
                foot = foot + along * cos
        return s + along, cos * dy - sin * dx

    def pose_at(
        self, s: np.ndarray | float, d: np.ndarray | float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World ``(x, y, heading)`` of road coordinates ``(s, d)`` (heading of the road)."""
        x = np.interp(s, self.s, self.x)
        centre_y, cos, sin, _ = self._lookup(np.asarray(x))
        return x - np.multiply(d, sin), centre_y + np.multiply(d, cos), np.arctan2(sin, cos)

    def curvature_at(self, s: np.ndarray | float) -> np.ndarray:
        """Signed curvature (1/m, + turns left) of the centreline at arc length ``s``."""
        return np.interp(s, self.s, self.curvature)

    def samples(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        """Centreline points every ``spacing`` metres of arc length over the whole road."""
        s = np.arange(self.s[0], self.s[-1], spacing)
        x, y, _ = self.pose_at(s)
        return x, y


@dataclass(frozen=True)
class Obstacles:
    """Static obstacles as arrays, sorted by ``s``. ``kind`` indexes :data:`OBSTACLE_KINDS`.

    ``x, y, heading`` are the world pose of each box centre; ``length`` runs along ``heading``;
    ``s, d`` are road coordinates of the centre; ``half_along`` / ``half_across`` are the
    half-extents of the footprint along and across the road.

    Example:
        >>> scene = build_scene("urban", 0)
        >>> obstacles = scene.obstacles
        >>> bool(np.all(np.diff(obstacles.s) >= 0)) and len(obstacles) > 10
        True
    """

    kind: np.ndarray
    variant: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    height: np.ndarray
    s: np.ndarray
    d: np.ndarray
    half_along: np.ndarray
    half_across: np.ndarray

    def __len__(self) -> int:
        return int(self.kind.size)

    def between(self, s_min: float, s_max: float) -> slice:
        """Slice of the obstacles whose centre ``s`` lies in ``[s_min, s_max)``."""
        first, last = np.searchsorted(self.s, (s_min, s_max))
        return slice(int(first), int(last))


@dataclass(frozen=True)
class WallRun:
    """One side of a roadside layer: segments ``[start, end)`` of ``s`` at a fixed offset.

    Example:
        >>> run = WallRun(12.0, np.array([0.0]), np.array([30.0]), np.array([9.0]), np.zeros(1))
        >>> run.offset
        12.0
    """

    offset: float
    start: np.ndarray
    end: np.ndarray
    height: np.ndarray
    variant: np.ndarray


@dataclass(frozen=True)
class RoadsideLayer:
    """Buildings, a tree line or a guard rail along both sides of the road.

    Example:
        >>> [layer.kind for layer in build_scene("highway", 0).roadside]
        ['trees', 'rail']
    """

    kind: str
    left: WallRun
    right: WallRun


@dataclass(frozen=True)
class Scene:
    """The static world of one prompt and seed.

    Layers in ``roadside`` are ordered from the outermost to the innermost. ``detail_seed``
    seeds purely visual detail (field stripes, weather particles).

    Example:
        >>> scene = build_scene("rural road at sunset", seed=3)
        >>> scene.style.layout, scene.style.lighting, scene.style.lanes
        ('rural', 'sunset', 2)
    """

    prompt: str
    seed: int
    style: Style
    road: Road
    obstacles: Obstacles
    roadside: tuple[RoadsideLayer, ...]
    detail_seed: int

    @property
    def start_lane(self) -> int:
        """The lane the car starts in: the rightmost."""
        return 0

    def with_obstacles(self, obstacles: Obstacles) -> Scene:
        """This scene with other obstacles (e.g. from :func:`obstacles_at`), for scenarios.

        Example:
            >>> scene = build_scene("rural", 0)
            >>> empty = obstacles_at(scene.road, [], [], [])
            >>> len(scene.with_obstacles(empty).obstacles)
            0
        """
        return dataclasses.replace(self, obstacles=obstacles)


def _road_headings(spec: LayoutSpec, rng: np.random.Generator) -> np.ndarray:
    """Heading per sample: straight and constant-curvature runs, smoothed, straight at start."""
    samples = int((ROAD_END_X - ROAD_START_X) / ROAD_STEP) + 1
    curvature = np.zeros(samples)
    index = int((CLEAR_START + 40.0 - ROAD_START_X) / ROAD_STEP)
    heading = 0.0
    while index < samples:
        length = rng.uniform(*spec.segment_length)
        count = int(length / ROAD_STEP)
        bend = 0.0
        if rng.random() >= spec.straight_probability:
            bend = rng.uniform(0.3, 1.0) * spec.max_curvature * rng.choice((-1.0, 1.0))
            if abs(heading + bend * length) > spec.max_heading:
                bend = -bend
            if abs(heading + bend * length) > spec.max_heading:
                bend = 0.0
        curvature[index : index + count] = bend
        heading += bend * ROAD_STEP * min(count, samples - index)
        index += count
    window = int(20.0 / ROAD_STEP)
    smooth = np.convolve(curvature, np.full(window, 1.0 / window), mode="same")
    headings = np.cumsum(smooth) * ROAD_STEP
    return np.clip(headings, -1.2, 1.2)


@dataclass
class _ObstacleList:
    """Obstacles under construction, in road coordinates."""

    kind: list[int]
    variant: list[int]
    s: list[float]
    d: list[float]
    yaw: list[float]

    def add(self, rng: np.random.Generator, kind: str, s: float, d: float, yaw: float) -> None:
        """Append one obstacle with a random colour variant."""
        self.kind.append(OBSTACLE_KINDS.index(kind))
        self.variant.append(int(rng.integers(OBSTACLE_VARIANTS[kind])))
        self.s.append(s)
        self.d.append(d)
        self.yaw.append(yaw)


def _place_lane_events(
    style: Style, spec: LayoutSpec, length: float, rng: np.random.Generator, out: _ObstacleList
) -> None:
    """Obstacles in the lanes, in well-spaced groups that never block every lane at once."""
    s = CLEAR_START + 15.0 + rng.exponential(spec.event_gap[1] / 2)
    kinds = np.asarray(spec.event_kinds) / sum(spec.event_kinds)
    while s < length - 200.0:
        kind = OBSTACLE_KINDS[int(rng.choice(len(OBSTACLE_KINDS), p=kinds))]
        blocked = 2 if style.lanes >= 3 and rng.random() < 0.3 else 1
        for lane in rng.choice(style.lanes, size=blocked, replace=False):
            centre = style.lane_offset(int(lane))
            if kind == "car":
                out.add(rng, kind, s + rng.uniform(-1, 1), centre + rng.uniform(-0.3, 0.3), 0.0)
                out.yaw[-1] = rng.normal(0.0, 0.06)
            elif kind == "barrier":
                out.add(rng, kind, s, centre + rng.uniform(-0.2, 0.2), 0.0)
            else:
                out.add(rng, kind, s, centre + rng.uniform(-1.0, 1.0), rng.uniform(-np.pi, np.pi))
        s += spec.event_gap[0] + rng.exponential(spec.event_gap[1])


def _place_roadside_obstacles(
    style: Style, length: float, rng: np.random.Generator, out: _ObstacleList
) -> None:
    """Parked cars, stalled cars on shoulders and pedestrians beside the lanes."""
    strip = style.half_lanes_width + style.shoulder_width / 2
    if style.layout == "urban":
        for side in (-1.0, 1.0):
            for s in np.arange(CLEAR_START, length - 50.0, 6.5):
                if rng.random() < 0.4:
                    out.add(rng, "car", s, side * strip, rng.normal(0.0, 0.02))
            walk = np.arange(CLEAR_START, length - 50.0, 1.0)
            for s in walk[rng.random(walk.size) < 1 / 14]:
                offset = style.road_half_width + rng.uniform(0.6, style.verge_width - 0.6)
                out.add(rng, "pedestrian", s, side * offset, rng.uniform(-np.pi, np.pi))
    elif style.layout == "highway":
        s = CLEAR_START + rng.exponential(300.0)
        while s < length - 50.0:
            kind = "car" if rng.random() < 0.7 else "barrier"
            out.add(rng, kind, s, -strip, rng.normal(0.0, 0.05))
            s += 60.0 + rng.exponential(350.0)
    else:
        s = CLEAR_START + rng.exponential(200.0)
        edge = style.road_half_width - 0.35
        while s < length - 50.0:
            side = rng.choice((-1.0, 1.0))
            out.add(rng, "pedestrian", s, side * edge, rng.uniform(-np.pi, np.pi))
            s += 40.0 + rng.exponential(220.0)


def obstacles_at(
    road: Road,
    kinds: Sequence[str],
    s: Sequence[float],
    d: Sequence[float],
    yaw: Sequence[float] | None = None,
    variant: Sequence[int] | None = None,
) -> Obstacles:
    """Obstacles of ``kinds`` centred at road coordinates ``(s, d)``, turned by ``yaw``
    (radians) from the road direction, sorted by ``s``.

    Example:
        >>> road = build_scene("rural", 0).road
        >>> obstacles = obstacles_at(road, ["barrier", "car"], [30.0, 20.0], [-1.6, 0.0])
        >>> [OBSTACLE_KINDS[kind] for kind in obstacles.kind], obstacles.s.tolist()
        (['car', 'barrier'], [20.0, 30.0])
    """
    order = np.argsort(np.asarray(s, dtype=np.float64), kind="stable")
    kind = np.array([OBSTACLE_KINDS.index(name) for name in kinds], dtype=np.int8)[order]
    s = np.asarray(s, dtype=np.float64)[order]
    d = np.asarray(d, dtype=np.float64)[order]
    yaw = np.zeros(s.size) if yaw is None else np.asarray(yaw, dtype=np.float64)[order]
    variant = np.zeros(s.size) if variant is None else np.asarray(variant)[order]
    sizes = np.array([OBSTACLE_SIZES[name] for name in OBSTACLE_KINDS])[kind].reshape(-1, 3)
    x, y, road_heading = road.pose_at(s, d)
    length, width = sizes[:, 0], sizes[:, 1]
    cos, sin = np.abs(np.cos(yaw)), np.abs(np.sin(yaw))
    return Obstacles(
        kind=kind,
        variant=variant.astype(np.int8),
        x=x,
        y=y,
        heading=road_heading + yaw,
        length=length,
        width=width,
        height=sizes[:, 2],
        s=s,
        d=d,
        half_along=(length * cos + width * sin) / 2,
        half_across=(length * sin + width * cos) / 2,
    )


def _make_obstacles(
    style: Style, spec: LayoutSpec, road: Road, rng: np.random.Generator
) -> Obstacles:
    """Place every obstacle of the scene."""
    placed = _ObstacleList([], [], [], [], [])
    _place_lane_events(style, spec, road.length, rng, placed)
    _place_roadside_obstacles(style, road.length, rng, placed)
    kinds = [OBSTACLE_KINDS[kind] for kind in placed.kind]
    return obstacles_at(road, kinds, placed.s, placed.d, placed.yaw, placed.variant)


def _wall_run(
    rng: np.random.Generator,
    kind: str,
    offset: float,
    length: float,
    run_length: tuple[float, float],
    gap: tuple[float, float],
    height: tuple[float, float],
) -> WallRun:
    """Random segments along one side, from behind the start to the end of the road."""
    starts, ends = [], []
    s = -100.0 + rng.uniform(0.0, gap[1])
    while s < length:
        end = s + rng.uniform(*run_length)
        starts.append(s)
        ends.append(end)
        s = end + rng.uniform(*gap)
    count = len(starts)
    return WallRun(
        offset=offset,
        start=np.asarray(starts),
        end=np.asarray(ends),
        height=rng.uniform(*height, size=count),
        variant=rng.integers(ROADSIDE_VARIANTS[kind], size=count),
    )


def _make_roadside(style: Style, length: float, rng: np.random.Generator) -> tuple:
    """Roadside layers for the layout, outermost first."""
    edge = style.road_half_width

    def layer(kind: str, offsets: tuple, **shape: tuple[float, float]) -> RoadsideLayer:
        left, right = (_wall_run(rng, kind, offset, length, **shape) for offset in offsets)
        return RoadsideLayer(kind, left, right)

    if style.layout == "urban":
        offsets = tuple(edge + style.verge_width + rng.uniform(0.5, 3.0) for _ in range(2))
        return (
            layer("building", offsets, run_length=(12, 35), gap=(0.0, 1.5), height=(8.0, 32.0)),
        )
    tree_range = (10.0, 22.0) if style.layout == "highway" else (5.0, 14.0)
    trees = layer(
        "trees",
        tuple(edge + rng.uniform(*tree_range) for _ in range(2)),
        run_length=(40, 250) if style.layout == "highway" else (20, 150),
        gap=(20, 200) if style.layout == "highway" else (30, 250),
        height=(7.0, 14.0) if style.layout == "highway" else (6.0, 14.0),
    )
    if style.layout == "rural":
        return (trees,)
    rail = layer(
        "rail", (edge + 0.6,) * 2, run_length=(length + 200,) * 2, gap=(0, 0), height=(0.8, 0.8)
    )
    return trees, rail


def _scene_rng(prompt: str, seed: int) -> np.random.Generator:
    """The Generator that draws the whole scene of ``prompt`` and ``seed``."""
    digest = hashlib.sha256(f"{len(prompt)}:{prompt}:{seed}".encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:16], "little"))


def build_scene(prompt: str, seed: int = 0) -> Scene:
    """Build the deterministic world of ``prompt`` and ``seed``.

    Example:
        >>> a, b = build_scene("city", 1), build_scene("city", 1)
        >>> bool(np.array_equal(a.obstacles.x, b.obstacles.x))
        True
    """
    rng = _scene_rng(prompt, seed)
    style = parse_style(prompt, rng)
    spec = LAYOUT_SPECS[style.layout]
    road = Road(_road_headings(spec, rng), ROAD_START_X)
    obstacles = _make_obstacles(style, spec, road, rng)
    roadside = _make_roadside(style, road.length, rng)
    logger.debug(
        "scene %r seed %d: %s, %d lanes, %d obstacles",
        prompt,
        seed,
        style,
        style.lanes,
        len(obstacles),
    )
    return Scene(
        prompt=prompt,
        seed=seed,
        style=style,
        road=road,
        obstacles=obstacles,
        roadside=roadside,
        detail_seed=int(rng.integers(2**62)),
    )


@functools.lru_cache(maxsize=64)
def cached_scene(prompt: str, seed: int) -> Scene:
    """:func:`build_scene`, reusing recent worlds (building is deterministic; scenes immutable).

    Example:
        >>> cached_scene("rural road", 3) is cached_scene("rural road", 3)
        True
    """
    return build_scene(prompt, seed)
