"""Top-down map of the embedded simulator's world: the road, obstacles, the car and its path.

The map is built from a ``SceneResponse`` (``sim.proto``), as answered by the embedded server's
``SimService/GetScene`` or rebuilt locally from prompt and seed by :func:`local_scene` (worlds
are deterministic), so both sources draw the same. Only the part near the car is drawn
(:meth:`RoadMap.near`), which keeps each logged map small and the view zoomed on the car.

Rerun's 2D views point y down; :func:`to_view` negates y so that north (+y in the world) is up.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.proto import sim_pb2
from oasis_torchrl.sim.scene import cached_scene
from oasis_torchrl.sim.simulator import scene_proto
from oasis_torchrl.sim.vehicle import VehicleParams

Color = tuple[int, int, int]

EDGE_COLOR: Color = (200, 200, 200)
CENTRE_COLOR: Color = (110, 110, 110)
PATH_COLOR: Color = (60, 220, 90)
CAR_COLOR: Color = (255, 255, 255)
CRASHED_COLOR: Color = (255, 40, 40)
OBSTACLE_COLORS: dict[str, Color] = {
    "car": (80, 140, 255),
    "barrier": (255, 160, 0),
    "pedestrian": (230, 60, 200),
}
OTHER_OBSTACLE_COLOR: Color = (180, 180, 60)
CAR_SIZE = (VehicleParams().length, VehicleParams().width)
"""``(length, width)`` of the ego car, metres."""
_SCENE_CACHE = 16


@functools.lru_cache(maxsize=_SCENE_CACHE)
def local_scene(prompt: str, seed: int) -> sim_pb2.SceneResponse:
    """The static world of ``prompt`` and ``seed`` as the embedded server reports it.

    Example:
        >>> scene = local_scene("rural road", 3)
        >>> scene.prompt, scene.seed, len(scene.centerline_x) > 100
        ('rural road', 3, True)
    """
    return scene_proto(cached_scene(prompt, int(seed)))


def to_view(points: np.ndarray) -> np.ndarray:
    """World ``[..., 2]`` metres to view coordinates (y negated: north up).

    Example:
        >>> to_view(np.array([[1.0, 2.0]])).tolist()
        [[1.0, -2.0]]
    """
    return points * np.array([1.0, -1.0])


def box_outlines(
    x: np.ndarray, y: np.ndarray, heading: np.ndarray, length: np.ndarray, width: np.ndarray
) -> np.ndarray:
    """Closed outlines ``[K, 5, 2]`` of oriented rectangles (centre, heading, length, width).

    Example:
        >>> box_outlines(*(np.array([v]) for v in (0.0, 0.0, 0.0, 4.0, 2.0)))[0, :2].tolist()
        [[2.0, 1.0], [-2.0, 1.0]]
    """
    corners = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0], [1.0, 1.0]])
    half = np.stack([np.asarray(length), np.asarray(width)], axis=-1)[:, None, :] / 2
    local = corners[None] * half  # [K, 5, 2] along / across the heading
    cos, sin = np.cos(heading)[:, None], np.sin(heading)[:, None]
    world_x = x[:, None] + cos * local[..., 0] - sin * local[..., 1]
    world_y = y[:, None] + sin * local[..., 0] + cos * local[..., 1]
    return np.stack([world_x, world_y], axis=-1)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` index ranges where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))


@dataclass(frozen=True)
class MapPatch:
    """What to draw near the car: polylines with one colour each, obstacle outlines likewise.

    Example:
        >>> patch = MapPatch([], [], obstacles=np.zeros((0, 5, 2)), obstacle_colors=[])
        >>> len(patch.road), patch.obstacles.shape
        (0, (0, 5, 2))
    """

    road: list[np.ndarray]
    road_colors: list[Color]
    obstacles: np.ndarray
    obstacle_colors: list[Color]


@dataclass(frozen=True)
class RoadMap:
    """Road polylines and obstacle outlines of one scene, in world metres.

    Example:
        >>> road = RoadMap.from_scene(local_scene("urban street", 1))
        >>> patch = road.near(np.array([0.0, 0.0]), radius=50.0)
        >>> len(patch.road) >= 3, patch.obstacles.shape[1:]
        (True, (5, 2))
    """

    centre: np.ndarray
    left: np.ndarray
    right: np.ndarray
    obstacle_outlines: np.ndarray
    obstacle_centres: np.ndarray
    obstacle_colors: list[Color]

    @classmethod
    def from_scene(cls, scene: sim_pb2.SceneResponse) -> RoadMap:
        """Road edges from the centreline and half width; obstacle outlines from their boxes."""
        centre = np.stack([np.asarray(scene.centerline_x), np.asarray(scene.centerline_y)], -1)
        if len(centre) < 2:
            raise ValueError(
                f"scene {scene.prompt!r} seed {scene.seed} has {len(centre)} centreline "
                "samples; a road needs at least 2"
            )
        tangent = np.gradient(centre, axis=0)
        tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-9)
        normal = np.stack([-tangent[:, 1], tangent[:, 0]], -1)  # + is left
        offset = normal * scene.road_half_width
        boxes = np.array(
            [(o.x, o.y, o.heading, o.length, o.width) for o in scene.obstacles], dtype=np.float64
        ).reshape(-1, 5)
        return cls(
            centre=centre,
            left=centre + offset,
            right=centre - offset,
            obstacle_outlines=box_outlines(*boxes.T),
            obstacle_centres=boxes[:, :2],
            obstacle_colors=[
                OBSTACLE_COLORS.get(o.kind, OTHER_OBSTACLE_COLOR) for o in scene.obstacles
            ],
        )

    def near(self, point: np.ndarray, radius: float) -> MapPatch:
        """The road and obstacles within ``radius`` metres of ``point`` (world ``[2]``)."""
        close = np.linalg.norm(self.centre - point, axis=-1) <= radius
        road, colors = [], []
        for start, stop in _runs(close):
            if stop - start < 2:
                continue
            for line, color in (
                (self.left, EDGE_COLOR),
                (self.right, EDGE_COLOR),
                (self.centre, CENTRE_COLOR),
            ):
                road.append(line[start:stop])
                colors.append(color)
        near = np.flatnonzero(
            np.linalg.norm(self.obstacle_centres - point, axis=-1) <= radius
        ).tolist()
        return MapPatch(
            road=road,
            road_colors=colors,
            obstacles=self.obstacle_outlines[near],
            obstacle_colors=[self.obstacle_colors[i] for i in near],
        )


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

    def recent_within(self, radius: float) -> np.ndarray:
        """The newest stretch of the trail that stays within ``radius`` of the newest point."""
        points = self.points()
        if len(points) == 0:
            return points
        far = np.flatnonzero(np.linalg.norm(points - points[-1], axis=-1) > radius)
        return points[far[-1] + 1 :] if len(far) else points
