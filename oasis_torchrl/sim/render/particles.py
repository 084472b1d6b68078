"""Rain streaks and snow flakes: sparse pixels that fall frame by frame."""

from __future__ import annotations

import numpy as np

from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.render.camera import CameraModel
from oasis_torchrl.sim.render.materials import material
from oasis_torchrl.sim.scene import Scene


class Particles:
    """Rain streaks or snow flakes per camera, falling deterministically with the frame index.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> index = np.zeros((3, 64, 96), np.uint8)
        >>> Particles(CameraModel(96, 64), build_scene("rural rain", 0)).draw(index,
        ...                                                                   np.array([0.0]))
        >>> bool((index > 0).any())
        True
    """

    def __init__(self, model: CameraModel, scene: Scene) -> None:
        self.model = model
        self.weather = scene.style.weather
        rng = np.random.default_rng(scene.detail_seed)
        area = model.width * model.height
        count = {"rain": area // 1500, "snow": area // 1000}.get(self.weather, 0)
        # [cameras, poses (broadcast), particles, pixels along the streak (broadcast)]
        shape = (len(CAMERAS), 1, count, 1)
        self._columns = rng.uniform(0, model.width, shape)
        self._phases = rng.uniform(0, model.height, shape)
        self._speeds = rng.uniform(0.7, 1.3, shape)
        if self.weather == "rain":
            self.length = max(2, model.height // 20)
            self.speed, self.slant, self.colour = model.height / 9, 0.2, material("rail") + 2
        else:
            self.length = 2 if model.width >= 256 else 1
            self.speed, self.slant, self.colour = model.height / 70, 0.0, material("barrier_white")

    def draw(self, index: np.ndarray, frames: np.ndarray) -> None:
        """Paint the particles into the index image ``[views, rows, columns]`` (camera-major
        views) of poses at ``frames`` (float64, one per pose)."""
        if self._columns.size == 0:
            return
        height, width = self.model.height, self.model.width
        frame = frames.reshape(1, -1, 1, 1)
        travel = self._phases + frame * self.speed * self._speeds
        top = travel % (height + self.length) - self.length
        steps = np.arange(self.length)
        rows = (top + steps).astype(np.intp)
        if self.weather == "snow":
            columns = self._columns + 3.0 * np.sin(0.15 * frame + self._phases) + steps
        else:
            columns = self._columns + self.slant * steps
        columns = columns.astype(np.intp)
        views = np.arange(len(CAMERAS) * frames.size).reshape(len(CAMERAS), -1, 1, 1)
        views, rows, columns = np.broadcast_arrays(views, rows, columns)
        valid = (rows >= 0) & (rows < height) & (columns >= 0) & (columns < width)
        flat = (views[valid] * height + rows[valid]) * index.shape[2] + columns[valid]
        index.reshape(-1)[flat] = self.colour
