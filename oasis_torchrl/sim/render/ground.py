"""The ground: road coordinates under the cameras and the ground rows of the index image.

Road coordinates ``(s, d)`` are exact at a few depths (:data:`DEPTH_SAMPLES`, log-spaced) under
knot columns (every ``knot`` pixels), interpolated to every row (linear in depth along a ray)
and column (the ground point of a row is linear in the column; only the road's gentle curvature
bends it). Each pixel then looks up its lateral texel in its row's profile (lanes, edge lines,
shoulders, verges, fields, at the row's depth band); the dashes are decided per row, where the
row crosses each dashed line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oasis_torchrl.sim.render.camera import FAR, CameraModel, Views
from oasis_torchrl.sim.render.lighting import Look
from oasis_torchrl.sim.render.materials import GROUND_BANDS, depth_bands
from oasis_torchrl.sim.render.textures import (
    FAR_TEXTURE_DEPTH,
    TEXTURE_COLUMN,
    TEXTURE_COLUMNS,
    TEXTURE_HALF_WIDTH,
    dashed_lines,
    ground_profiles,
)
from oasis_torchrl.sim.render.threads import Part, thread_array
from oasis_torchrl.sim.scene import Road, Scene
from oasis_torchrl.sim.style import Style

#: Depths (log-spaced, nearest ground row to FAR) at which road coordinates are exact.
DEPTH_SAMPLES = 64


@dataclass(frozen=True)
class GroundPlan:
    """Per view, ground row and knot interval: texel index (float32) at the interval's
    first column and its step per column."""

    start: np.ndarray
    step: np.ndarray


def interpolation_weights(
    samples: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(lower, upper, weight)``: linear interpolation at ``points`` of values given at
    ``samples`` (monotonic; points outside are clamped to the ends), weight on ``upper``.

    Example:
        >>> lower, upper, weight = interpolation_weights(np.array([3.0, 2.0, 1.0]),
        ...                                               np.array([2.5]))
        >>> lower.tolist(), upper.tolist(), weight.tolist()
        ([1], [0], [0.5])
    """
    descending = samples[0] > samples[-1]
    ascending = samples[::-1] if descending else samples
    upper = np.clip(np.searchsorted(ascending, points), 1, samples.size - 1)
    lower = upper - 1
    span = ascending[upper] - ascending[lower]
    weight = np.clip((points - ascending[lower]) / span, 0.0, 1.0)
    if descending:
        lower, upper = samples.size - 1 - lower, samples.size - 1 - upper
    return lower, upper, weight


class Ground:
    """Ground sampling and drawing for one camera model; :meth:`prepare` for each scene.

    Example:
        >>> from oasis_torchrl.sim.render.lighting import scene_look
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> from oasis_torchrl.sim.world import World
        >>> scene = build_scene("rural", 0)
        >>> ground = Ground(CameraModel(96, 64))
        >>> ground.prepare(scene, scene_look(scene.style))
        >>> s, d = ground.samples(Views.of([World(scene, 0.05).state], scene.road), scene.road)
        >>> s.shape
        (3, 64, 25)
    """

    def __init__(self, model: CameraModel) -> None:
        self.model = model
        depths = model.row_depths()
        #: The first image row drawn as ground (rows above are sky or far haze).
        self.first_row = first_row = int(np.searchsorted(-depths, -FAR, side="left"))
        self._depths = depths[first_row:]
        self._first_near_row = int(np.searchsorted(-self._depths, -FAR_TEXTURE_DEPTH))
        #: Depths at which road coordinates are sampled, far first.
        self.sample_depths = np.geomspace(self._depths[-1], FAR, DEPTH_SAMPLES)[::-1].copy()
        self._row_samples = interpolation_weights(self.sample_depths, self._depths)
        knots = np.arange(0, model.padded_width + 1, model.knot)
        self._knot_slopes = model.column_slopes(knots)
        self._knot_steps = np.arange(model.knot, dtype=np.float32)
        self._style: Style | None = None

    def prepare(self, scene: Scene, look: Look) -> None:
        """Bake the scene's ground profiles and the depth band of every ground row."""
        self._style = scene.style
        self._bands = depth_bands(self._depths, GROUND_BANDS, look.band_distance)
        self._profiles = ground_profiles(scene).ravel()
        self._dashed_lines = dashed_lines(scene.style)

    def samples(self, views: Views, road: Road) -> tuple[np.ndarray, np.ndarray]:
        """Road coordinates ``(s, d)`` of the ground at the sample depths (far first) under the
        knot columns: ``[views, DEPTH_SAMPLES, knots]`` each."""
        ray_x = views.forward[:, None, 0] + self._knot_slopes * views.right[:, None, 0]
        ray_y = views.forward[:, None, 1] + self._knot_slopes * views.right[:, None, 1]
        x = views.x[:, None, None] + self.sample_depths[:, None] * ray_x[:, None, :]
        y = views.y[:, None, None] + self.sample_depths[:, None] * ray_y[:, None, :]
        return road.locate(x, y)

    def plan(self, s_samples: np.ndarray, d_samples: np.ndarray) -> GroundPlan:
        """Texel indices of the ground at the knots of every row, and their steps per column.

        A texel index is the row's profile (dash variant and depth band) plus the lateral
        texel; it is linear in the column within a knot interval (exact for a straight road,
        the road's curvature is gentle over one interval).
        """
        d_rows = self._by_row(d_samples)
        columns = (d_rows + TEXTURE_HALF_WIDTH) / TEXTURE_COLUMN
        np.clip(columns, 0.0, TEXTURE_COLUMNS - 0.01, out=columns)
        columns += self._row_profiles(s_samples, d_rows)[..., None]
        columns = columns.astype(np.float32)
        step = np.diff(columns, axis=-1) / np.float32(self.model.knot)
        return GroundPlan(columns[..., :-1, None], step[..., None])

    def draw_rows(self, plan: GroundPlan, index: np.ndarray, part: Part) -> None:
        """Look up the ground pixels of ``part`` of the index image in their profiles."""
        views, rows = part
        first = self.first_row
        ground = slice(max(rows.start - first, 0), max(rows.stop - first, 0))
        if ground.stop <= ground.start:
            return
        start, step = plan.start[views, ground], plan.step[views, ground]
        texel = thread_array("ground_texel", (*start.shape[:-1], self.model.knot), np.float32)
        gather = thread_array("ground_gather", texel.shape, np.intp)
        np.multiply(step, self._knot_steps, out=texel)
        texel += start
        np.copyto(gather, texel, casting="unsafe")
        pixels = index[views, first + ground.start : first + ground.stop]
        np.take(self._profiles, gather, out=pixels.reshape(gather.shape), mode="clip")

    def _by_row(self, samples: np.ndarray) -> np.ndarray:
        """Values at the sample depths (axis -2) interpolated to every ground row (linear in
        depth along a knot ray, exact for a straight road)."""
        lower, upper, weight = self._row_samples
        weight = weight[:, None]
        return samples[..., lower, :] * (1.0 - weight) + samples[..., upper, :] * weight

    def _row_profiles(self, s_samples: np.ndarray, d_rows: np.ndarray) -> np.ndarray:
        """Per view and ground row, the first entry of its lateral profile: the variant for
        the dashes where the row crosses each dashed line, and the row's depth band."""
        style = self._require_style()
        views, rows = np.ogrid[: d_rows.shape[0], : d_rows.shape[1]]
        lower, upper, weight = self._row_samples
        variant = np.zeros(d_rows.shape[:-1], dtype=np.intp)
        for bit, (offset, _) in enumerate(self._dashed_lines):
            side = d_rows - offset
            crossed = side[..., :-1] * side[..., 1:] <= 0.0
            knot = np.argmax(crossed, axis=-1)
            before, after = side[views, rows, knot], side[views, rows, knot + 1]
            fraction = np.divide(
                before, before - after, out=np.zeros_like(before), where=before != after
            )
            s_knots = [
                s_samples[views, lower, column] * (1.0 - weight)
                + s_samples[views, upper, column] * weight
                for column in (knot, knot + 1)
            ]
            s = s_knots[0] + fraction * (s_knots[1] - s_knots[0])
            dash = crossed.any(axis=-1) & (s % style.dash_period < style.dash_length)
            variant |= dash.astype(np.intp) << bit
        variant[:, : self._first_near_row] = 2 ** len(self._dashed_lines)
        return (variant * GROUND_BANDS + self._bands) * TEXTURE_COLUMNS

    def _require_style(self) -> Style:
        if self._style is None:
            raise RuntimeError("Ground.prepare(scene, look) must be called before drawing")
        return self._style
