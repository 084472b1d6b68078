"""Roadside layers (buildings, tree lines, guard rails): walls at a fixed lateral offset.

Each column's wall distance comes from where the knots' ground rays cross the layer's offset;
the wall is a vertical span of that column, patterned (windows, trunks, posts) in small-integer
arithmetic per pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oasis_torchrl.sim.render.camera import CAMERA_HEIGHT, FAR, CameraModel
from oasis_torchrl.sim.render.materials import OBJECT_BANDS, TRANSPARENT, depth_bands
from oasis_torchrl.sim.render.textures import (
    ROADSIDE_TEXEL,
    ROW_PATTERNS,
    RowPattern,
    roadside_materials,
)
from oasis_torchrl.sim.render.threads import Part, thread_array
from oasis_torchrl.sim.scene import RoadsideLayer, WallRun


@dataclass(frozen=True)
class WallPlan:
    """One roadside layer, ready to draw: per view the rows its spans cover
    (``first_row <= row < last_row``), per view and column the span's parameters (see
    :meth:`Roadside.draw_rows`)."""

    first_row: np.ndarray
    last_row: np.ndarray
    texels_per_row: np.ndarray
    top_texel: np.ndarray
    pattern: RowPattern
    first_material: np.ndarray
    difference: np.ndarray
    see_through: bool
    depth: np.ndarray
    top: np.ndarray


def segments_at(
    layer: RoadsideLayer, s: np.ndarray, is_left: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column: whether a segment of ``layer`` stands at ``s``, its height and variant.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> layer = build_scene("urban", 0).roadside[0]
        >>> present, height, variant = segments_at(layer, np.array([50.0]), np.array([True]))
        >>> present.shape, height.shape
        ((1,), (1,))
    """
    present = np.zeros(s.shape, dtype=bool)
    height = np.zeros(s.shape)
    variant = np.zeros(s.shape, dtype=np.intp)
    runs: tuple[tuple[WallRun, np.ndarray], ...] = ((layer.left, is_left), (layer.right, ~is_left))
    for run, side in runs:
        index = np.searchsorted(run.start, s, side="right") - 1
        safe = np.maximum(index, 0)
        inside = side & (index >= 0) & (s < run.end[safe])
        present |= inside
        height = np.where(inside, run.height[safe], height)
        variant = np.where(inside, run.variant[safe], variant)
    if layer.kind == "trees":  # an uneven crown line
        height = height * (1.0 + 0.1 * np.sin(1.3 * s) + 0.06 * np.sin(3.7 * s + 1.0))
    return present, height, variant


class Roadside:
    """Planning and drawing of roadside layers for one camera model, from the ground's road
    coordinates at its sample depths.

    Example:
        >>> roadside = Roadside(CameraModel(96, 64), np.geomspace(400.0, 2.0, 64))
        >>> roadside.model.knot
        4
    """

    def __init__(self, model: CameraModel, sample_depths: np.ndarray) -> None:
        self.model = model
        self._samples = sample_depths
        self._knot_fraction = np.arange(model.knot) / model.knot
        self._row_offsets = model.row_offsets()

    def plan(
        self,
        layer: RoadsideLayer,
        s_samples: np.ndarray,
        d_samples: np.ndarray,
        band_distance: float,
    ) -> WallPlan | None:
        """Where one roadside layer stands in every view's columns (None: nowhere)."""
        model = self.model
        inverse, s, is_left = self._wall_columns(layer, s_samples, d_samples)
        present, height, variant = segments_at(layer, s, is_left)
        visible = present & (inverse > 1.0 / FAR)
        if not visible.any():
            return None
        inverse = np.where(visible, inverse, 0.0)
        depth = np.where(visible, 1.0 / np.where(visible, inverse, 1.0), np.inf)
        top = np.where(
            visible, model.horizon - model.focal * (height - CAMERA_HEIGHT) * inverse, np.inf
        )
        bottom = np.where(visible, model.horizon + model.focal * CAMERA_HEIGHT * inverse, -np.inf)
        first_row = np.clip(np.floor(top.min(axis=1)), 0, model.height).astype(np.intp)
        last_row = np.clip(np.ceil(bottom.max(axis=1)), 0, model.height).astype(np.intp)
        texels_per_row = np.where(visible, depth, 0.0) / (model.focal * ROADSIDE_TEXEL)
        top_texel = np.where(visible, np.minimum(height / ROADSIDE_TEXEL, 30000.0), 0.0)
        bands = depth_bands(depth, OBJECT_BANDS, band_distance)
        along = np.floor(np.where(visible, s, 0.0) / ROADSIDE_TEXEL).astype(np.intp)
        first_material, second_material = roadside_materials(layer.kind, along, variant, bands)
        return WallPlan(
            first_row=first_row,
            last_row=last_row,
            texels_per_row=texels_per_row.astype(np.float32),
            top_texel=top_texel.astype(np.uint16),
            pattern=ROW_PATTERNS[layer.kind],
            first_material=first_material,
            difference=first_material ^ second_material,
            see_through=bool(np.any(second_material == TRANSPARENT)),
            depth=depth.astype(np.float32),
            top=top,
        )

    def draw_rows(
        self, plan: WallPlan, index: np.ndarray, part: Part, depth: np.ndarray | None
    ) -> None:
        """Draw the wall spans of ``part``.

        Per pixel, in small integers: the height above ground in texels (negative below
        ground, so huge as uint16), whether it is under the wall's top, and which of the
        column's two materials it shows.
        """
        views, part_rows = part
        first_row, last_row = plan.first_row[views], plan.last_row[views]
        rows = slice(
            max(part_rows.start, int(first_row.min())), min(part_rows.stop, int(last_row.max()))
        )
        if rows.stop <= rows.start:
            return
        shape = (first_row.size, rows.stop - rows.start, self.model.padded_width)
        level = thread_array("wall_level", shape, np.float32)
        np.multiply(self._row_offsets[rows, None], plan.texels_per_row[views, None], out=level)
        level += CAMERA_HEIGHT / ROADSIDE_TEXEL
        texel = thread_array("wall_texel", shape, np.int16)
        np.copyto(texel, level, casting="unsafe")
        texel = texel.view(np.uint16)
        opaque = thread_array("wall_opaque", shape, np.bool_)
        second = thread_array("wall_second", shape, np.bool_)
        np.less(texel, plan.top_texel[views, None], out=opaque)
        if first_row.size > 1:  # the rows are the views' union: keep each view's own rows
            number = np.arange(rows.start, rows.stop)
            opaque &= ((number >= first_row[:, None]) & (number < last_row[:, None]))[..., None]
        pattern = plan.pattern
        if pattern.mask is not None:
            texel &= pattern.mask
            texel -= pattern.low
        np.less(texel, pattern.span, out=second)
        value = thread_array("wall_value", shape, np.uint8)
        np.multiply(second.view(np.uint8), plan.difference[views, None], out=value)
        value ^= plan.first_material[views, None]
        if plan.see_through:
            np.not_equal(value, TRANSPARENT, out=second)
            opaque &= second
        pixels = index[views, rows]
        value -= pixels
        value *= opaque.view(np.uint8)
        pixels += value
        if depth is not None:
            np.copyto(depth[views, rows], plan.depth[views, None], where=opaque)

    def _wall_samples(
        self, layer: RoadsideLayer, s_samples: np.ndarray, d_samples: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per view and knot: inverse depth (0: no wall), ``s`` and side (true: left) where
        the knot's ground ray first meets the layer (interpolated between depth samples)."""
        left, right = layer.left.offset, -layer.right.offset
        near_first = ((d_samples >= left) | (d_samples <= right))[:, ::-1]
        last = self._samples.size - 1
        outside = last - np.argmax(near_first, axis=1)[:, None]
        inside = np.minimum(outside + 1, last)
        d_in = np.take_along_axis(d_samples, inside, 1)[:, 0]
        d_out = np.take_along_axis(d_samples, outside, 1)[:, 0]
        is_left = d_out >= left
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = (np.where(is_left, left, right) - d_in) / (d_out - d_in)
        weight = np.clip(np.nan_to_num(weight), 0.0, 1.0)
        z_in, z_out = self._samples[inside[:, 0]], self._samples[outside[:, 0]]
        s_in = np.take_along_axis(s_samples, inside, 1)[:, 0]
        s_out = np.take_along_axis(s_samples, outside, 1)[:, 0]
        inverse = np.where(near_first.any(axis=1), 1.0 / (z_in + weight * (z_out - z_in)), 0.0)
        return inverse, s_in + weight * (s_out - s_in), is_left

    def _wall_columns(
        self, layer: RoadsideLayer, s_samples: np.ndarray, d_samples: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per view and column: inverse depth (0: no wall), ``s`` and side.

        Perspective-correct between knots that see the same wall; across a change of wall (or
        its end) each column takes its nearest knot.
        """
        inverse, s, is_left = self._wall_samples(layer, s_samples, d_samples)
        shape = (inverse.shape[0], -1)
        fraction = self._knot_fraction
        before, after = inverse[:, :-1, None], inverse[:, 1:, None]
        side_before, side_after = is_left[:, :-1, None], is_left[:, 1:, None]
        smooth = (before > 0) & (after > 0) & (side_before == side_after)
        blended = before + fraction * (after - before)
        weighted = s[:, :-1, None] * before
        weighted = weighted + fraction * (s[:, 1:, None] * after - weighted)
        first_half = fraction < 0.5
        nearest_inverse = np.where(first_half, before, after)
        nearest_s = np.where(first_half, s[:, :-1, None], s[:, 1:, None])
        column_s = np.where(smooth, weighted / np.where(smooth, blended, 1.0), nearest_s)
        column_side = np.where(first_half, side_before, side_after)
        return (
            np.where(smooth, blended, nearest_inverse).reshape(shape),
            column_s.reshape(shape),
            column_side.reshape(shape),
        )
