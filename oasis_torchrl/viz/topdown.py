"""The top-down view: a window that follows the car, drawn from the scene the server reports.

The scene is a ``SceneResponse`` (``sim.proto``: road centreline, width, lanes, obstacles, the
car's size), asked of the server through the protocol
(:class:`~oasis_torchrl.client.scenes.SceneSource`). Everything is drawn in the car's frame,
heading up: view ``x`` is metres to the car's right, view ``y`` metres behind it (rerun's 2D
views point y down), so a fixed :class:`Window` (20 m behind to 60 m ahead by default, wide
enough for a highway) follows the car. The road is a filled band, its edges and lane lines are
drawn over it, obstacles and the car are filled to their real size (a line of radius half the
width, whose round caps end at the box's ends).

Example:
    >>> from oasis_torchrl.proto import sim_pb2
    >>> scene = sim_pb2.SceneResponse(
    ...     centerline_x=np.arange(0.0, 200.0, 2.0), centerline_y=np.zeros(100),
    ...     road_half_width=5.0, lanes=2, lane_width=3.5, ego_length=4.5, ego_width=1.9,
    ...     obstacles=[sim_pb2.Obstacle(kind="car", x=30.0, y=1.75, length=4.5, width=1.9)])
    >>> view = RoadMap.from_scene(scene).view(np.array([10.0, 0.0]), heading=0.0)
    >>> view.obstacles.ends.round(2).tolist()  # 20 m ahead (-y), 1.75 m to the left (-x)
    [[[-1.75, -18.7], [-1.75, -21.3]]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oasis_torchrl.proto import sim_pb2

Color = tuple[int, int, int]

ROAD_COLOR: Color = (72, 72, 78)
EDGE_COLOR: Color = (235, 235, 235)
LANE_COLOR: Color = (210, 210, 150)
PATH_COLOR: Color = (60, 220, 90)
CAR_COLOR: Color = (255, 255, 255)
CRASHED_COLOR: Color = (255, 40, 40)
OBSTACLE_COLORS: dict[str, Color] = {
    "car": (80, 140, 255),
    "barrier": (255, 160, 0),
    "pedestrian": (230, 60, 200),
}
OTHER_OBSTACLE_COLOR: Color = (180, 180, 60)
CAR_SIZE = (4.5, 1.9)
"""``(length, width)`` of the car when no scene reports it (a replay without a server), metres."""
EDGE_RADIUS = 0.2
LANE_RADIUS = 0.12
PATH_RADIUS = 0.3
PATH_EVERY = 2
"""The path is drawn through every other position of the car (10 a second)."""
DASH = (3.0, 6.0)
"""Lane-line dashes: metres painted, metres gap."""
MAP_SPACING = 5.0
"""Metres between the points the road and its lines are drawn through (a scene reports one
every 2 m; a bend of 50 m radius strays 6 cm from chords of 5 m)."""
SCALE_COLOR: Color = (235, 235, 235)
SCALE_RADIUS = 0.15
DRAW_ORDER = {"road": 1.0, "lanes": 2.0, "obstacles": 3.0, "path": 4.0, "car": 5.0, "scale": 6.0}
"""Rerun draw order of each layer (higher is drawn over lower)."""


@dataclass(frozen=True)
class Window:
    """The part of the world around the car the view shows, metres in the car's frame.

    Example:
        >>> Window().x_range, Window().y_range
        ((-15.0, 15.0), (-60.0, 20.0))
    """

    behind: float = 20.0
    ahead: float = 60.0
    half_width: float = 15.0

    def __post_init__(self) -> None:
        if min(self.behind, self.ahead) < 0 or self.half_width <= 0:
            raise ValueError(f"a top-down window needs non-negative extents, got {self}")

    @property
    def x_range(self) -> tuple[float, float]:
        """View ``x`` (metres to the right) shown."""
        return (-self.half_width, self.half_width)

    @property
    def y_range(self) -> tuple[float, float]:
        """View ``y`` (metres behind; ahead is negative) shown."""
        return (-self.ahead, self.behind)

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which view points ``[..., 2]`` lie in the window grown by ``margin`` metres."""
        x, y = points[..., 0], points[..., 1]
        return (
            (np.abs(x) <= self.half_width + margin)
            & (y >= -self.ahead - margin)
            & (y <= self.behind + margin)
        )


DEFAULT_WINDOW = Window()


def scale_bar(window: Window) -> tuple[np.ndarray, int]:
    """A scale bar for the view: a strip ``[4, 2]`` (view coordinates, ticked ends) one metre
    in from the window's bottom-left corner, and its length in metres (10, or 5 in a window
    narrower than 12 m).

    Example:
        >>> strip, metres = scale_bar(Window())
        >>> metres, strip.tolist()
        (10, [[-14.0, 18.0], [-14.0, 19.0], [-4.0, 19.0], [-4.0, 18.0]])
    """
    metres = 10 if 2 * window.half_width >= 12 else 5
    left, y = window.x_range[0] + 1.0, window.y_range[1] - 1.0
    right = left + metres
    return np.array([[left, y - 1.0], [left, y], [right, y], [right, y - 1.0]]), metres


def car_frame(points: np.ndarray, car: np.ndarray, heading: float) -> np.ndarray:
    """World points ``[..., 2]`` (metres, +y north) to view coordinates of the car at ``car``
    heading ``heading`` (radians): x to its right, y behind it.

    Example:
        >>> north = car_frame(np.array([[1.0, 2.0], [0.0, 5.0]]), np.zeros(2), heading=np.pi / 2)
        >>> (north.round(6) + 0.0).tolist()  # 1 m east is to the right of a car heading north
        [[1.0, -2.0], [0.0, -5.0]]
    """
    offset = points - car
    cos, sin = np.cos(heading), np.sin(heading)
    ahead = offset[..., 0] * cos + offset[..., 1] * sin
    left = -offset[..., 0] * sin + offset[..., 1] * cos
    return np.stack([-left, -ahead], axis=-1)


@dataclass(frozen=True)
class Capsules:
    """Filled boxes drawn as thick lines: segment ends ``[K, 2, 2]`` (view), radii, colours.

    Example:
        >>> boxes = Capsules.of_boxes(np.zeros((1, 2)), np.zeros(1), np.array([4.0]),
        ...                           np.array([2.0]), [(255, 255, 255)])
        >>> boxes.ends.tolist(), boxes.radii.tolist()
        ([[[0.0, 1.0], [0.0, -1.0]]], [1.0])
    """

    ends: np.ndarray
    radii: np.ndarray
    colors: list[Color]

    @classmethod
    def of_boxes(
        cls,
        centres: np.ndarray,
        headings: np.ndarray,
        lengths: np.ndarray,
        widths: np.ndarray,
        colors: list[Color],
    ) -> Capsules:
        """Boxes in view coordinates: centres ``[K, 2]``, headings (0 = ahead, the view's -y,
        counter-clockwise positive), lengths and widths ``[K]``; the caps end at the box ends."""
        half = np.maximum(lengths - widths, 0.0)[:, None] / 2
        along = np.stack([-np.sin(headings), -np.cos(headings)], axis=-1)
        ends = np.stack([centres - along * half, centres + along * half], axis=1)
        return cls(ends.reshape(-1, 2, 2), widths / 2, colors)

    def __len__(self) -> int:
        return len(self.ends)


@dataclass(frozen=True)
class MapView:
    """One step's view of the map: road band, markings and obstacles, in view coordinates.

    ``road`` strips are drawn with radius ``road_radius`` (the filled surface), ``markings``
    with ``marking_radii`` and ``marking_colors``, one per strip.
    """

    road: list[np.ndarray]
    road_radius: float
    markings: list[np.ndarray]
    marking_radii: list[float]
    marking_colors: list[Color]
    obstacles: Capsules


@dataclass(frozen=True)
class RoadMap:
    """A scene's road (centreline samples, their normals and distances along the road, the
    offsets of the lines painted on it) and obstacles, in world metres; :meth:`view` cuts out
    and turns what a :class:`Window` around the car shows.

    Example:
        >>> scene = sim_pb2.SceneResponse(centerline_x=[0.0, 2.0, 4.0], centerline_y=[0.0] * 3,
        ...                               road_half_width=4.0, lanes=2, lane_width=3.0)
        >>> RoadMap.from_scene(scene).line_offsets.tolist()  # road edges, lane edges, divider
        [-4.0, 4.0, -3.0, 3.0, 0.0]
    """

    centre: np.ndarray
    normal: np.ndarray
    along: np.ndarray
    half_width: float
    line_offsets: np.ndarray
    dashed: np.ndarray
    obstacle_centres: np.ndarray
    obstacle_headings: np.ndarray
    obstacle_sizes: np.ndarray
    obstacle_colors: list[Color]
    car_size: tuple[float, float]

    @classmethod
    def from_scene(cls, scene: sim_pb2.SceneResponse) -> RoadMap:
        """The map of a ``SceneResponse`` (a road needs at least two centreline samples)."""
        centre = np.stack([np.asarray(scene.centerline_x), np.asarray(scene.centerline_y)], -1)
        if len(centre) < 2:
            raise ValueError(
                f"scene {scene.prompt!r} seed {scene.seed} has {len(centre)} centreline "
                "samples; a road needs at least 2"
            )
        centre = _resampled(centre, MAP_SPACING)
        tangent = np.gradient(centre, axis=0)
        tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-9)
        half = scene.road_half_width
        offsets, dashed = [-half, half], [False, False]
        if scene.lanes and scene.lane_width > 0:
            lanes_half = scene.lanes * scene.lane_width / 2
            if lanes_half < half:  # shoulders: the lane edges are lines of their own
                offsets += [-lanes_half, lanes_half]
                dashed += [False, False]
            offsets += [-lanes_half + k * scene.lane_width for k in range(1, scene.lanes)]
            dashed += [True] * (scene.lanes - 1)
        boxes = np.array(
            [(o.x, o.y, o.heading, o.length, o.width) for o in scene.obstacles], np.float64
        ).reshape(-1, 5)
        return cls(
            centre=centre,
            normal=np.stack([-tangent[:, 1], tangent[:, 0]], -1),  # + is left
            along=np.concatenate(
                ([0.0], np.cumsum(np.linalg.norm(np.diff(centre, axis=0), axis=-1)))
            ),
            half_width=half,
            line_offsets=np.array(offsets),
            dashed=np.array(dashed),
            obstacle_centres=boxes[:, :2],
            obstacle_headings=boxes[:, 2],
            obstacle_sizes=boxes[:, 3:],
            obstacle_colors=[
                OBSTACLE_COLORS.get(o.kind, OTHER_OBSTACLE_COLOR) for o in scene.obstacles
            ],
            car_size=(scene.ego_length or CAR_SIZE[0], scene.ego_width or CAR_SIZE[1]),
        )

    def view(self, car: np.ndarray, heading: float, window: Window | None = None) -> MapView:
        """What ``window`` shows around the car at world ``car`` ``[2]`` heading ``heading``."""
        window = window or DEFAULT_WINDOW
        centre = car_frame(self.centre, car, heading)
        shown = window.contains(centre, margin=self.half_width + 2.0)
        road, markings, radii, colors = [], [], [], []
        for start, stop in _runs(shown):
            if stop - start < 2:
                continue
            road.append(centre[start:stop])
            normal = car_frame(self.normal[start:stop], np.zeros(2), heading)
            for offset, dashed in zip(self.line_offsets, self.dashed, strict=True):
                line = centre[start:stop] + offset * normal
                strips = _dashes(line, self.along[start:stop]) if dashed else [line]
                markings += strips
                radii += [LANE_RADIUS if dashed else EDGE_RADIUS] * len(strips)
                colors += [LANE_COLOR if dashed else EDGE_COLOR] * len(strips)
        return MapView(
            road, self.half_width, markings, radii, colors, self._obstacles(car, heading, window)
        )

    def _obstacles(self, car: np.ndarray, heading: float, window: Window) -> Capsules:
        centres = car_frame(self.obstacle_centres, car, heading)
        near = np.flatnonzero(window.contains(centres, margin=self.obstacle_sizes.max(initial=0)))
        return Capsules.of_boxes(
            centres[near],
            self.obstacle_headings[near] - heading,
            self.obstacle_sizes[near, 0],
            self.obstacle_sizes[near, 1],
            [self.obstacle_colors[i] for i in near.tolist()],
        )


def car_capsule(size: tuple[float, float], color: Color) -> Capsules:
    """The car itself: at the view's origin, heading up.

    Example:
        >>> car_capsule((4.5, 1.9), CAR_COLOR).ends[0, :, 1].round(2).tolist()
        [1.3, -1.3]
    """
    length, width = size
    return Capsules.of_boxes(
        np.zeros((1, 2)), np.zeros(1), np.array([length]), np.array([width]), [color]
    )


def _resampled(line: np.ndarray, spacing: float) -> np.ndarray:
    """A polyline ``[K, 2]`` through points ``spacing`` metres apart along it (and its end).

    Example:
        >>> _resampled(np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [6.0, 0.0]]), 5.0).tolist()
        [[0.0, 0.0], [5.0, 0.0], [6.0, 0.0]]
    """
    along = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=-1))))
    grid = np.append(np.arange(0.0, along[-1], spacing), along[-1])
    return np.stack([np.interp(grid, along, line[:, 0]), np.interp(grid, along, line[:, 1])], -1)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` index ranges where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))


def _dashes(line: np.ndarray, along: np.ndarray) -> list[np.ndarray]:
    """A polyline ``[K, 2]`` cut into the painted stretches of ``DASH``, as two-point strips.

    ``along`` is each point's distance along the road: the dashes are painted on the road, so
    they stay put while the window moves over them.
    """
    period = sum(DASH)
    first = np.floor(along[0] / period) * period
    starts = np.arange(first, along[-1], period)
    ends = np.minimum(starts + DASH[0], along[-1])
    starts = np.maximum(starts, along[0])
    keep = ends > starts
    stretches = np.stack([starts[keep], ends[keep]], -1)
    xs = np.interp(stretches, along, line[:, 0])
    ys = np.interp(stretches, along, line[:, 1])
    return list(np.stack([xs, ys], axis=-1))


class Trail:
    """The last ``capacity`` positions of the car (a fixed-size ring buffer).

    Example:
        >>> trail = Trail(capacity=3)
        >>> trail.extend(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]))
        >>> trail.points()[:, 0].tolist()
        [1.0, 2.0, 3.0]
    """

    def __init__(self, capacity: int) -> None:
        if capacity < 2:
            raise ValueError(f"a trail needs a capacity of at least 2 points, got {capacity}")
        self._buffer = np.zeros((capacity, 2))
        self._count = 0

    def clear(self) -> None:
        """Forget every position (a new episode)."""
        self._count = 0

    def extend(self, points: np.ndarray) -> None:
        """Append positions ``[K, 2]`` (non-finite ones are skipped)."""
        points = points[np.isfinite(points).all(-1)][-len(self._buffer) :]
        index = (self._count + np.arange(len(points))) % len(self._buffer)
        self._buffer[index] = points
        self._count += len(points)

    def points(self) -> np.ndarray:
        """The stored positions, oldest first (``[<= capacity, 2]``)."""
        capacity = len(self._buffer)
        if self._count <= capacity:
            return self._buffer[: self._count].copy()
        return np.roll(self._buffer, -(self._count % capacity), axis=0)
