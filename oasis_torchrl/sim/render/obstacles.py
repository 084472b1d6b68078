"""Obstacles (boxes) rasterised together for every view.

Visible vertical faces become column spans (a vertical face projects to a quad with vertical
sides), spans become pixel runs, painted far to near; low boxes also paint their back faces,
which shows their top. Walls in front of an obstacle cut its runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from oasis_torchrl.sim.render.camera import (
    CAMERA_HEIGHT,
    HORIZONTAL_FOV,
    NEAR,
    OBSTACLE_FAR,
    CameraModel,
    Views,
)
from oasis_torchrl.sim.render.materials import OBJECT_BANDS, depth_bands
from oasis_torchrl.sim.render.roadside import WallPlan
from oasis_torchrl.sim.render.textures import OBSTACLE_TEXTURE_START, obstacle_textures
from oasis_torchrl.sim.scene import Scene

#: Box corners in (along, across) units of the half extents, counter-clockwise.
_BOX_CORNERS = np.array([[1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0]])


@dataclass(frozen=True)
class Faces:
    """Obstacle faces to draw, far to near per view: view, bottom-edge endpoints in camera
    coordinates (right, forward), texture coordinate along the face at each end, height and
    texture id."""

    view: np.ndarray
    x0: np.ndarray
    z0: np.ndarray
    w0: np.ndarray
    x1: np.ndarray
    z1: np.ndarray
    w1: np.ndarray
    height: np.ndarray
    texture: np.ndarray

    def clipped(self) -> Faces:
        """The faces cut at the near plane (faces wholly behind it dropped)."""
        keep = (self.z0 >= NEAR) | (self.z1 >= NEAR)
        view, x0, z0, w0, x1, z1, w1, height, texture = (
            getattr(self, field.name)[keep] for field in fields(self)
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            cut0 = np.clip((NEAR - z0) / (z1 - z0), 0.0, 1.0)
            cut1 = np.clip((NEAR - z1) / (z0 - z1), 0.0, 1.0)
        behind0, behind1 = z0 < NEAR, z1 < NEAR
        return Faces(
            view,
            np.where(behind0, x0 + cut0 * (x1 - x0), x0),
            np.where(behind0, NEAR, z0),
            np.where(behind0, w0 + cut0 * (w1 - w0), w0),
            np.where(behind1, x1 + cut1 * (x0 - x1), x1),
            np.where(behind1, NEAR, z1),
            np.where(behind1, w1 + cut1 * (w0 - w1), w1),
            height,
            texture,
        )


@dataclass(frozen=True)
class ObstacleGeometry:
    """What rasterising needs of a scene's obstacles, computed once per scene: footprint
    corners (counter-clockwise), the next corner of each, heights and texture ids.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> geometry = ObstacleGeometry.of(build_scene("urban", 0))
        >>> geometry.corner_x.shape[1]
        4
    """

    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    corner_x: np.ndarray
    corner_y: np.ndarray
    facing: np.ndarray
    height: np.ndarray
    texture: np.ndarray
    textures: np.ndarray

    @classmethod
    def of(cls, scene: Scene) -> ObstacleGeometry:
        """The geometry of ``scene``'s obstacles."""
        obstacles = scene.obstacles
        cos, sin = np.cos(obstacles.heading)[:, None], np.sin(obstacles.heading)[:, None]
        along = _BOX_CORNERS[:, 0] * (obstacles.length / 2)[:, None]
        across = _BOX_CORNERS[:, 1] * (obstacles.width / 2)[:, None]
        corner_x = obstacles.x[:, None] + along * cos - across * sin
        corner_y = obstacles.y[:, None] + along * sin + across * cos
        # Outward normal of face i (corner i to i + 1, counter-clockwise) and its offset: a
        # face looks at a point p when normal . p + offset > 0.
        normal_x = np.roll(corner_y, -1, axis=1) - corner_y
        normal_y = corner_x - np.roll(corner_x, -1, axis=1)
        offset = -(normal_x * corner_x + normal_y * corner_y)
        return cls(
            s=obstacles.s,
            x=obstacles.x,
            y=obstacles.y,
            corner_x=corner_x,
            corner_y=corner_y,
            facing=np.stack([normal_x, normal_y, offset]),
            height=obstacles.height,
            texture=OBSTACLE_TEXTURE_START[obstacles.kind] + obstacles.variant,
            textures=obstacle_textures().ravel(),
        )

    def visible_faces(self, views: Views) -> Faces | None:
        """Per view, the vertical faces of obstacles in view: faces towards the camera, plus
        the back faces of boxes lower than the camera (what stays visible of those is the
        top), ordered far to near."""
        first = np.searchsorted(self.s, views.s - 30.0)
        end = np.searchsorted(self.s, views.s + OBSTACLE_FAR)
        near = slice(int(first.min()), int(end.max()))
        corner_x, corner_y = self.corner_x[near], self.corner_y[near]
        if corner_x.size == 0:
            return None
        right, forward = views.to_camera(corner_x, corner_y)
        spread = math.tan(HORIZONTAL_FOV / 2) * forward
        in_view = (forward.max(axis=2) > NEAR) & (forward.min(axis=2) < OBSTACLE_FAR)
        in_view &= ((right - spread).min(axis=2) < 0.0) & ((right + spread).max(axis=2) > 0.0)
        # ``near`` spans every pose's window; each view keeps only the obstacles of its own.
        number = np.arange(near.start, near.stop)
        in_view &= (number >= first[:, None]) & (number < end[:, None])
        normal_x, normal_y, offset = self.facing[:, near]
        x, y = views.x[:, None, None], views.y[:, None, None]
        front = normal_x * x + normal_y * y + offset > 0.0
        height = self.height[near]
        drawn = (front | (height < CAMERA_HEIGHT)[:, None]) & in_view[:, :, None]
        view, obstacle, face = np.nonzero(drawn)
        if view.size == 0:
            return None
        distance = np.hypot(self.x[near] - views.x[:, None], self.y[near] - views.y[:, None])
        order = np.lexsort((front[view, obstacle, face], -distance[view, obstacle], view))
        view, obstacle, face = view[order], obstacle[order], face[order]
        after = (face + 1) % 4
        return Faces(
            view,
            right[view, obstacle, face],
            forward[view, obstacle, face],
            np.zeros(view.size),
            right[view, obstacle, after],
            forward[view, obstacle, after],
            np.ones(view.size),
            height[obstacle],
            self.texture[near][obstacle],
        ).clipped()

    def draw(
        self,
        views: Views,
        model: CameraModel,
        walls: list[WallPlan],
        band_distance: float,
        index: np.ndarray,
        depth: np.ndarray | None,
    ) -> None:
        """Rasterise every visible obstacle face into the index image (and ``depth``) as
        pixel runs, far to near per view."""
        faces = self.visible_faces(views)
        if faces is None:
            return
        spans = face_spans(faces, model, walls, band_distance)
        if spans is None:
            return
        rows, first_flat, texture_base, texel_start, texel_step, span_depth = spans
        count = int(rows.sum())
        if count == 0:
            return
        starts = np.cumsum(rows) - rows
        local = np.arange(count) - np.repeat(starts, rows)
        texel = np.repeat(texel_start, rows) - local * np.repeat(texel_step, rows)
        texel = np.clip(texel, 0, 7).astype(np.intp) << 3
        texel += np.repeat(texture_base, rows)
        flat = np.repeat(first_flat, rows) + local * model.padded_width
        # Runs are ordered far to near; NumPy assigns repeated indices in order, so the last
        # (nearest) write wins, as in a painter's algorithm.
        index.reshape(-1)[flat] = self.textures[texel]
        if depth is not None:
            depth.reshape(-1)[flat] = np.repeat(span_depth, rows)


def face_spans(
    faces: Faces, model: CameraModel, walls: list[WallPlan], band_distance: float
) -> tuple[np.ndarray, ...] | None:
    """Per covered column of every face: its vertical run of pixels and how to texture it.

    Returns ``(rows, first_flat, texture_base, texel_start, texel_step, depth)`` per run:
    pixel count, flat index of the top pixel in the index image, texture offset (depth band,
    texture, column), texture row at the top pixel and its change per pixel down, and depth.
    """
    u0 = model.width / 2 + model.focal * faces.x0 / faces.z0
    u1 = model.width / 2 + model.focal * faces.x1 / faces.z1
    inverse0, inverse1 = 1.0 / faces.z0, 1.0 / faces.z1
    swap = u0 > u1
    u0, u1 = np.where(swap, u1, u0), np.where(swap, u0, u1)
    inverse0, inverse1 = np.where(swap, inverse1, inverse0), np.where(swap, inverse0, inverse1)
    w0, w1 = np.where(swap, faces.w1, faces.w0), np.where(swap, faces.w0, faces.w1)
    first = np.clip(np.ceil(u0 - 0.5), 0, model.width).astype(np.intp)
    widths = np.maximum(np.clip(np.ceil(u1 - 0.5), 0, model.width).astype(np.intp) - first, 0)
    total = int(widths.sum())
    if total == 0:
        return None
    face = np.repeat(np.arange(widths.size), widths)
    column = np.arange(total) - np.repeat(np.cumsum(widths) - widths, widths) + first[face]
    view = faces.view[face]
    along = (column + 0.5 - u0[face]) / (u1 - u0)[face]
    inverse = inverse0[face] + along * (inverse1 - inverse0)[face]
    weighted = (w0 * inverse0)[face] + along * (w1 * inverse1 - w0 * inverse0)[face]
    depth = 1.0 / inverse
    bottom = model.horizon + model.focal * CAMERA_HEIGHT * inverse
    top = model.horizon - model.focal * (faces.height[face] - CAMERA_HEIGHT) * inverse
    first_row = np.clip(np.ceil(top - 0.5), 0, model.height)
    end_row = np.clip(np.ceil(bottom - 0.5), 0, model.height)
    for wall in walls:
        hidden = depth > wall.depth[view, column]
        wall_top = np.maximum(np.ceil(wall.top[view, column] - 0.5), first_row)
        end_row = np.where(hidden, np.minimum(end_row, wall_top), end_row)
    texels = OBSTACLE_TEXTURE_START[-1] * 64
    bands = depth_bands(depth, OBJECT_BANDS, band_distance)
    texture_column = np.clip((weighted / inverse * 8).astype(np.intp), 0, 7)
    step = 8.0 / (bottom - top)
    first_flat = (view * model.height + first_row.astype(np.intp)) * model.padded_width
    return (
        np.maximum(end_row - first_row, 0).astype(np.intp),
        first_flat + column,
        bands * texels + faces.texture[face] * 64 + texture_column,
        (bottom - first_row - 0.5) * step,
        step,
        depth.astype(np.float32),
    )
