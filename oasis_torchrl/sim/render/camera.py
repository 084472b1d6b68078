"""The three cameras: placement on the car, intrinsics, and the views of one or more poses.

Cameras: pinhole, no roll, no pitch, :data:`CAMERA_HEIGHT` above the ground, yawed by
:data:`CAMERA_YAWS` (+ is right) from the car heading, horizontal field of view
:data:`HORIZONTAL_FOV`, square pixels. Without pitch the horizon is the middle row and the ground
depth of a row is ``height * focal / (row - horizon)``: one number per row.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.scene import Road
from oasis_torchrl.sim.vehicle import VehicleState

#: Camera yaw relative to the car heading, radians, + is right.
CAMERA_YAWS = dict(zip(CAMERAS, (-math.pi / 4, 0.0, math.pi / 4), strict=True))
HORIZONTAL_FOV = math.radians(80.0)
CAMERA_HEIGHT = 1.4
#: Cameras sit this far ahead of the car's centre (the windscreen).
CAMERA_FORWARD = 1.0
NEAR = 0.3
#: Ground, walls and obstacles beyond this depth are not drawn (horizon haze instead).
FAR = 400.0
OBSTACLE_FAR = 250.0


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics shared by the three cameras, and everything that depends only on them.

    Example:
        >>> model = CameraModel(768, 512)
        >>> round(model.focal, 1), model.knot, model.padded_width
        (457.6, 32, 768)
    """

    width: int
    height: int

    @property
    def focal(self) -> float:
        """Focal length in pixels."""
        return self.width / 2 / math.tan(HORIZONTAL_FOV / 2)

    @property
    def horizon(self) -> float:
        """Image y (continuous, pixel centres at +0.5) of the horizon."""
        return self.height / 2

    @property
    def knot(self) -> int:
        """Column spacing of the exact ground samples (a power of two, ~1/24 of the width)."""
        return 1 << max(1, int(math.log2(max(2, self.width // 24))))

    @property
    def padded_width(self) -> int:
        """Width rounded up to whole knot intervals (the index image's row stride)."""
        return -(-self.width // self.knot) * self.knot

    def row_depths(self) -> np.ndarray:
        """Ground depth of each row (inf at and above the horizon)."""
        below = np.arange(self.height) + 0.5 - self.horizon
        with np.errstate(divide="ignore"):
            return np.where(below > 0, CAMERA_HEIGHT * self.focal / below, np.inf)

    def row_offsets(self) -> np.ndarray:
        """Height of each row's pixel centre above the horizon, in pixels (float32)."""
        return (self.horizon - np.arange(self.height) - 0.5).astype(np.float32)

    def column_slopes(self, columns: np.ndarray) -> np.ndarray:
        """Tangent of each column's ray angle (+ right) for pixel centres at ``columns``."""
        return (columns + 0.5 - self.width / 2) / self.focal


@dataclass(frozen=True)
class Views:
    """The cameras of one or more car poses, one entry per view (camera-major: view
    ``camera * poses + pose``): position and road position of the pose, axes of the camera.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> from oasis_torchrl.sim.world import World
        >>> scene = build_scene("rural", 0)
        >>> views = Views.of([World(scene, 0.05).state] * 2, scene.road)
        >>> views.x.shape
        (6,)
    """

    x: np.ndarray
    y: np.ndarray
    s: np.ndarray
    forward: np.ndarray
    right: np.ndarray

    @classmethod
    def of(cls, cars: Sequence[VehicleState], road: Road) -> Views:
        """Where the cameras of every pose in ``cars`` are and where they look."""
        x = np.array([car.x + CAMERA_FORWARD * math.cos(car.heading) for car in cars])
        y = np.array([car.y + CAMERA_FORWARD * math.sin(car.heading) for car in cars])
        s, _ = road.locate(x, y)
        heading = np.array([car.heading for car in cars])
        yaws = np.array([CAMERA_YAWS[name] for name in CAMERAS])
        yaw = (heading - yaws[:, None]).ravel()
        cos, sin = np.cos(yaw), np.sin(yaw)
        cameras = len(CAMERAS)
        return cls(
            np.tile(x, cameras),
            np.tile(y, cameras),
            np.tile(s, cameras),
            np.stack([cos, sin], 1),
            np.stack([sin, -cos], 1),
        )

    @property
    def count(self) -> int:
        """Number of views (cameras x poses)."""
        return self.x.size

    def to_camera(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera coordinates ``(right, forward)`` of world points, ``[views, *x.shape]``."""
        shape = (-1,) + (1,) * np.ndim(x)
        dx, dy = x - self.x.reshape(shape), y - self.y.reshape(shape)
        right = dx * self.right[:, 0].reshape(shape) + dy * self.right[:, 1].reshape(shape)
        forward = dx * self.forward[:, 0].reshape(shape) + dy * self.forward[:, 1].reshape(shape)
        return right, forward
