"""Vectorised software renderer of the car's three cameras.

Cameras: pinhole, no roll, no pitch, :data:`CAMERA_HEIGHT` above the ground, yawed by
:data:`CAMERA_YAWS` (+ is right) from the car heading, horizontal field of view
:data:`HORIZONTAL_FOV`, square pixels. Without pitch the horizon is the middle row and the ground
depth of a row is ``height * focal / (row - horizon)``: one number per row.

Several car poses (the 4 frames of a simulator step) are drawn in one pass, so the per-call
overhead of the many small NumPy calls that plan a frame is shared: every per-column and
per-object step runs over all views (cameras x poses) at once. The frames are a ``uint8``
palette-index image ``[views, rows, columns]``. The 256-entry palette holds every material at
several depth bands with light (ambient, night headlights) and distance fog baked in, so fog
and headlights cost nothing per pixel:

- sky: one gradient level per row (static per resolution);
- ground: road coordinates ``(s, d)`` are exact at a few depths under knot columns (every
  ``knot`` pixels), interpolated to every row (linear in depth along a ray) and column (the
  ground point of a row is linear in the column; only the road's gentle curvature bends it).
  Each pixel then looks up its lateral texel in its row's profile (lanes, edge lines, shoulders,
  verges, fields, at the row's depth band); the dashes are decided per row, where the row
  crosses each dashed line;
- roadside layers (buildings, tree lines, guard rails) are walls at a fixed lateral offset: each
  column's wall distance comes from where the knots' rays cross that offset, and the wall is a
  vertical span of that column, patterned (windows, trunks, posts) in small-integer arithmetic;
- obstacles (boxes) are rasterised together: visible vertical faces become column spans
  (a vertical face projects to a quad with vertical sides), spans become pixel runs, painted far
  to near; low boxes also paint their back faces, which shows their top;
- rain streaks and snow flakes are sparse pixels that fall frame by frame.

Palette indices become packed RGB by three table gathers per 4 pixels (:class:`_QuadPalette`).
Per-pixel work is a few large NumPy calls over all views without temporaries (frame-sized
allocations cost page faults), and on large frames runs as independent parts (per view and
half image) on a small thread pool (NumPy releases the GIL inside its loops). The same drawing
code optionally fills a metric depth buffer (distance along the camera axis, ``inf`` for sky)
for :meth:`Renderer.depth`.
"""

from __future__ import annotations

import functools
import logging
import math
import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields
from typing import TypeVar

import numpy as np

from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.scene import (
    OBSTACLE_KINDS,
    OBSTACLE_VARIANTS,
    ROADSIDE_VARIANTS,
    RoadsideLayer,
    Scene,
    Style,
    WallRun,
)
from oasis_torchrl.sim.vehicle import VehicleState

logger = logging.getLogger(__name__)
T = TypeVar("T")

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

GROUND_MATERIALS = ("grass", "grass_alt", "verge", "asphalt", "line_white", "line_yellow")
OBJECT_MATERIALS = (
    *(f"facade_{variant}" for variant in range(ROADSIDE_VARIANTS["building"])),
    "window",
    "foliage",
    "foliage_dark",
    "trunk",
    "rail",
    *(f"car_{variant}" for variant in range(OBSTACLE_VARIANTS["car"])),
    "glass",
    "tyre",
    "barrier_red",
    "barrier_white",
    "skin",
)
GROUND_BANDS = 16
OBJECT_BANDS = 8
SKY_LEVELS = 16


def _palette_layout() -> dict[str, tuple[int, int]]:
    """``material -> (first palette index, number of depth bands)``; 256 entries at most."""
    layout, index = {}, 0
    groups = ((GROUND_MATERIALS, GROUND_BANDS), (("sky",), SKY_LEVELS))
    for names, bands in (*groups, (OBJECT_MATERIALS, OBJECT_BANDS)):
        for name in names:
            layout[name] = (index, bands)
            index += bands
    if index > TRANSPARENT:
        raise AssertionError(f"palette needs {index} entries, {TRANSPARENT} are available")
    return layout


#: Marks see-through texels of roadside walls (never a palette entry).
TRANSPARENT = 255
PALETTE = _palette_layout()


def material(name: str) -> int:
    """First palette index of a material (its nearest depth band).

    Example:
        >>> material("grass")
        0
    """
    return PALETTE[name][0]


_DAY_COLOURS = {
    "grass": (0.33, 0.47, 0.22),
    "grass_alt": (0.46, 0.52, 0.27),
    "verge": (0.63, 0.62, 0.60),
    "asphalt": (0.26, 0.26, 0.28),
    "line_white": (0.90, 0.90, 0.88),
    "line_yellow": (0.90, 0.72, 0.18),
    "facade_0": (0.66, 0.45, 0.36),
    "facade_1": (0.58, 0.60, 0.63),
    "facade_2": (0.76, 0.70, 0.56),
    "window": (0.18, 0.24, 0.32),
    "foliage": (0.20, 0.38, 0.17),
    "foliage_dark": (0.11, 0.24, 0.10),
    "trunk": (0.32, 0.23, 0.15),
    "rail": (0.72, 0.74, 0.76),
    "car_0": (0.72, 0.10, 0.10),
    "car_1": (0.14, 0.26, 0.62),
    "car_2": (0.88, 0.88, 0.86),
    "car_3": (0.22, 0.22, 0.24),
    "glass": (0.08, 0.10, 0.13),
    "tyre": (0.04, 0.04, 0.04),
    "barrier_red": (0.90, 0.30, 0.08),
    "barrier_white": (0.96, 0.96, 0.96),
    "skin": (0.82, 0.62, 0.48),
}
_SNOW_COLOURS = {
    "grass": (0.90, 0.92, 0.95),
    "grass_alt": (0.82, 0.85, 0.90),
    "verge": (0.88, 0.89, 0.92),
    "foliage": (0.55, 0.64, 0.58),
}
_SKIES = {  # lighting -> (zenith, horizon)
    "day": ((0.33, 0.52, 0.82), (0.74, 0.82, 0.90)),
    "sunset": ((0.30, 0.27, 0.50), (1.00, 0.56, 0.28)),
    "night": ((0.01, 0.015, 0.04), (0.05, 0.06, 0.10)),
}
_WEATHER_SKIES = {"rain": ((0.45, 0.47, 0.50), 0.75), "snow": ((0.80, 0.82, 0.86), 0.7)}
_WEATHER_SKIES["fog"] = ((0.72, 0.74, 0.76), 0.9)
_FOG_DISTANCES = {"clear": 900.0, "rain": 170.0, "snow": 260.0, "fog": 40.0}
HEADLIGHT_REACH = 22.0


@dataclass(frozen=True)
class Look:
    """Colours and light of a scene style (colours are RGB in [0, 1]).

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> scene_look(build_scene("city at night", 0).style).headlight > 0
        True
    """

    colours: dict[str, np.ndarray]
    sky_zenith: np.ndarray
    sky_horizon: np.ndarray
    tint: np.ndarray
    ambient: float
    headlight: float
    fog_distance: float
    band_distance: float
    emissive: dict[str, np.ndarray]


def scene_look(style: Style) -> Look:
    """The :class:`Look` of a style: lighting sets sky and light, weather sky, fog, ground.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> scene_look(build_scene("rural fog", 0).style).fog_distance
        40.0
    """
    colours = {name: np.asarray(rgb, dtype=np.float64) for name, rgb in _DAY_COLOURS.items()}
    if style.weather == "snow":
        colours.update({name: np.asarray(rgb) for name, rgb in _SNOW_COLOURS.items()})
    if style.weather == "rain":
        colours["asphalt"] = colours["asphalt"] * 0.75
    zenith, horizon = (np.asarray(rgb, dtype=np.float64) for rgb in _SKIES[style.lighting])
    if style.weather in _WEATHER_SKIES:
        grey, weight = _WEATHER_SKIES[style.weather]
        shade = np.asarray(grey) * (0.12 if style.lighting == "night" else 1.0)
        zenith, horizon = (weight * shade + (1 - weight) * sky for sky in (zenith, horizon))
    night = style.lighting == "night"
    ambient = {"day": 1.0, "sunset": 0.8, "night": 0.14}[style.lighting]
    tint = {"day": (1.0, 1.0, 1.0), "sunset": (1.1, 0.82, 0.62), "night": (0.75, 0.82, 1.0)}
    fog_distance = _FOG_DISTANCES[style.weather]
    return Look(
        colours=colours,
        sky_zenith=zenith,
        sky_horizon=horizon,
        tint=np.asarray(tint[style.lighting]),
        ambient=ambient * (0.62 if style.weather == "rain" else 1.0),
        headlight=1.1 if night else 0.0,
        fog_distance=fog_distance,
        band_distance=min(fog_distance, 30.0 if night else 180.0),
        emissive={"window": np.array([1.0, 0.85, 0.5])} if night else {},
    )


def depth_bands(depth: np.ndarray, bands: int, band_distance: float) -> np.ndarray:
    """Depth band of each depth: equal steps of ``1 - exp(-depth / band_distance)`` up to FAR.

    Example:
        >>> depth_bands(np.array([0.0, 50.0, np.inf]), 8, 100.0).tolist()
        [0, 3, 7]
    """
    scale = bands / -math.expm1(-FAR / band_distance)
    level = -np.expm1(-np.asarray(depth) / band_distance) * scale
    return np.minimum(level, bands - 1).astype(np.intp)


def _band_depths(bands: int, band_distance: float) -> np.ndarray:
    """The representative depth of each band (the inverse of :func:`depth_bands` at centres)."""
    span = -math.expm1(-FAR / band_distance)
    return -band_distance * np.log1p(-(np.arange(bands) + 0.5) / bands * span)


def build_palette(look: Look, camera_yaw: float, sky_levels: np.ndarray) -> np.ndarray:
    """The 256-colour RGB palette ``[256, 3]`` of one camera (headlights light mostly the front
    camera).

    ``sky_levels`` are the gradient positions (0 horizon, 1 zenith) of the sky entries.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> look = scene_look(build_scene("rural", 0).style)
        >>> build_palette(look, 0.0, np.linspace(0, 1, SKY_LEVELS)).shape
        (256, 3)
    """
    palette = np.zeros((256, 3))
    fog_colour = look.sky_horizon
    headlight = look.headlight * max(math.cos(camera_yaw), 0.0) ** 2
    for name, (first, bands) in PALETTE.items():
        if name == "sky":
            weight = sky_levels[:, None]
            palette[first : first + bands] = weight * look.sky_zenith + (1 - weight) * fog_colour
            continue
        depth = _band_depths(bands, look.band_distance)[:, None]
        light = look.ambient * look.tint + headlight * np.exp(-depth / HEADLIGHT_REACH)
        colour = look.emissive.get(name, look.colours[name] * light)
        fog = -np.expm1(-depth / look.fog_distance)
        palette[first : first + bands] = (1 - fog) * colour + fog * fog_colour
    return (np.clip(palette, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


# Ground: lateral profiles of materials across the road (TEXTURE_COLUMN metres per texel). The
# only along-road detail is the dashing of the lane lines; a row of the image crosses each line
# about once, so each row picks a profile variant: dashed line ``k`` drawn iff bit ``k`` is set,
# or the far variant (beyond FAR_TEXTURE_DEPTH, where dashes would alias) with thin solid lines.
TEXTURE_COLUMN = 0.125
TEXTURE_COLUMNS = 1024
TEXTURE_HALF_WIDTH = TEXTURE_COLUMN * TEXTURE_COLUMNS / 2
FAR_TEXTURE_DEPTH = 45.0
LINE_HALF_WIDTH = 0.125
#: Depths (log-spaced, nearest ground row to FAR) at which road coordinates are exact.
DEPTH_SAMPLES = 64


def dashed_lines(style: Style) -> list[tuple[float, str]]:
    """Lateral offset and material of each dashed line between lanes.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> dashed_lines(build_scene("rural", 0).style)
        [(0.0, 'line_yellow')]
    """
    lines = []
    for boundary in range(1, style.lanes):
        offset = -style.half_lanes_width + boundary * style.lane_width
        centre_line = style.layout == "rural" and 2 * boundary == style.lanes
        lines.append((offset, "line_yellow" if centre_line else "line_white"))
    return lines


def ground_profiles(scene: Scene) -> np.ndarray:
    """Palette indices across the road: ``[variants, GROUND_BANDS, TEXTURE_COLUMNS]``.

    Variant ``v < 2**lines`` draws dashed line ``k`` iff bit ``k`` of ``v`` is set; the last
    variant draws every dashed line as a thin solid line (for far rows).

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> profiles = ground_profiles(build_scene("highway", 0))
        >>> int(profiles[0, 0, TEXTURE_COLUMNS // 2]) == material("asphalt")
        True
    """
    style = scene.style
    d = -TEXTURE_HALF_WIDTH + (np.arange(TEXTURE_COLUMNS) + 0.5) * TEXTURE_COLUMN
    base = np.full(TEXTURE_COLUMNS, material("grass"), dtype=np.uint8)
    outside = np.abs(d) - style.road_half_width
    if style.layout == "rural":
        rng = np.random.default_rng(scene.detail_seed)
        stripe = np.cumsum(rng.uniform(3.0, 9.0, size=64))
        field = np.searchsorted(stripe, np.maximum(outside - 4.0, 0.0)) % 2 == 1
        base[field & (outside > 4.0)] = material("grass_alt")
    if style.layout == "urban":
        base[outside < style.verge_width] = material("verge")
    base[outside <= 0.0] = material("asphalt")
    base[np.abs(np.abs(d) - style.half_lanes_width) < LINE_HALF_WIDTH] = material("line_white")
    lines = dashed_lines(style)
    profiles = np.repeat(base[None], 2 ** len(lines) + 1, axis=0)
    for bit, (offset, name) in enumerate(lines):
        near = np.abs(d - offset) < LINE_HALF_WIDTH
        drawn = (np.arange(2 ** len(lines)) >> bit) & 1 == 1
        profiles[np.ix_(drawn, near)] = material(name)
        profiles[-1, np.abs(d - offset) < TEXTURE_COLUMN / 2] = material(name)
    bands = np.arange(GROUND_BANDS, dtype=np.uint8)
    return profiles[:, None, :] + bands[None, :, None]


# Roadside walls: heights in texels of ROADSIDE_TEXEL metres, counted in uint8 (254 = 63.5 m).
ROADSIDE_TEXEL = 0.25


@dataclass(frozen=True)
class _RowPattern:
    """Which wall heights (texel rows ``h``) use a column's second material:
    ``(h & mask) - low < span`` in uint16 arithmetic, or ``h < span`` without a mask."""

    span: int
    mask: int | None = None
    low: int = 0


#: Windows 1.5-3.5 m up every 4 m floor; tree trunks below 2.5 m; rail posts below 0.5 m.
_ROW_PATTERNS = {
    "building": _RowPattern(8, mask=15, low=6),
    "trees": _RowPattern(10),
    "rail": _RowPattern(2),
}


def _roadside_materials(
    kind: str, along: np.ndarray, variant: np.ndarray, band: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per column (``along``: texel column along the road): the wall's two palette indices.

    The second one is used where the kind's :class:`_RowPattern` matches (windows, trunks,
    posts); :data:`TRANSPARENT` lets what is behind show through.
    """
    if kind == "building":
        facades = np.array([material(f"facade_{v}") for v in range(ROADSIDE_VARIANTS[kind])])
        first = facades[variant]
        window = (along % 16 >= 4) & (along % 16 < 12)
        second = np.where(window, material("window"), first)
    elif kind == "trees":
        blotch = (along // 12 + variant) % 3 == 0
        first = np.where(blotch, material("foliage_dark"), material("foliage"))
        second = np.where(along % 16 // 2 == 3, material("trunk"), TRANSPARENT)
    else:
        first = np.full(along.shape, material("rail"))
        second = np.where(along % 8 == 0, material("rail"), TRANSPARENT)
    second = np.where(second == TRANSPARENT, TRANSPARENT, second + band)
    return (first + band).astype(np.uint8), second.astype(np.uint8)


#: Obstacle texture ids: each kind's variants, consecutively.
_OBSTACLE_TEXTURE_START = np.cumsum([0] + [OBSTACLE_VARIANTS[kind] for kind in OBSTACLE_KINDS])


def _obstacle_texture(kind: str, variant: int) -> np.ndarray:
    """Material bases of an obstacle's vertical faces: ``[8 rows up, 8 columns along]``."""
    height, width = np.meshgrid(np.arange(8), np.arange(8), indexing="ij")
    if kind == "car":
        names = np.full(height.shape, f"car_{variant}", dtype=object)
        names[0] = "tyre"
        names[5:7, 1:7] = "glass"
    elif kind == "barrier":
        names = np.where((height + width) // 3 % 2 == 0, "barrier_red", "barrier_white")
    else:
        names = np.full(height.shape, f"car_{variant}", dtype=object)
        names[:4] = "glass"
        names[7] = "skin"
    return np.vectorize(material)(names).astype(np.uint8)


def obstacle_textures() -> np.ndarray:
    """All obstacle textures with the depth band added: ``[OBJECT_BANDS, textures, 8, 8]``
    (rows up the face, columns along it; textures: each kind's variants in turn).

    Example:
        >>> obstacle_textures().shape
        (8, 9, 8, 8)
    """
    base = np.stack(
        [
            _obstacle_texture(kind, variant)
            for kind in OBSTACLE_KINDS
            for variant in range(OBSTACLE_VARIANTS[kind])
        ]
    )
    return base[None] + np.arange(OBJECT_BANDS, dtype=np.uint8)[:, None, None, None]


def _segments_at(
    layer: RoadsideLayer, s: np.ndarray, is_left: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column: whether a segment of ``layer`` stands at ``s``, its height and variant."""
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

    def column_slopes(self, columns: np.ndarray) -> np.ndarray:
        """Tangent of each column's ray angle (+ right) for pixel centres at ``columns``."""
        return (columns + 0.5 - self.width / 2) / self.focal


#: The cameras in the order of the renderer's camera axis.

#: Part of the per-pixel work: the views and the image rows it covers.
_Part = tuple[slice, slice]


@dataclass(frozen=True)
class _Views:
    """The cameras of one or more car poses, one entry per view (camera-major: view
    ``camera * poses + pose``): position and road position of the pose, axes of the camera."""

    x: np.ndarray
    y: np.ndarray
    s: np.ndarray
    forward: np.ndarray
    right: np.ndarray

    def to_camera(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera coordinates ``(right, forward)`` of world points, ``[views, *x.shape]``."""
        shape = (-1,) + (1,) * np.ndim(x)
        dx, dy = x - self.x.reshape(shape), y - self.y.reshape(shape)
        right = dx * self.right[:, 0].reshape(shape) + dy * self.right[:, 1].reshape(shape)
        forward = dx * self.forward[:, 0].reshape(shape) + dy * self.forward[:, 1].reshape(shape)
        return right, forward


@dataclass(frozen=True)
class _WallPlan:
    """One roadside layer, ready to draw: per view the rows its spans cover
    (``first_row <= row < last_row``), per view and column the span's parameters (see
    :meth:`Renderer._draw_wall_rows`)."""

    first_row: np.ndarray
    last_row: np.ndarray
    texels_per_row: np.ndarray
    top_texel: np.ndarray
    pattern: _RowPattern
    first_material: np.ndarray
    difference: np.ndarray
    see_through: bool
    depth: np.ndarray
    top: np.ndarray


@dataclass(frozen=True)
class _GroundPlan:
    """Per view, ground row and knot interval: texel index (float32) at the interval's
    first column and its step per column."""

    start: np.ndarray
    step: np.ndarray


class Renderer:
    """Draws the three cameras of a car in a :class:`~oasis_torchrl.sim.scene.Scene`.

    Several poses of the car (e.g. the 4 frames of a step) can be drawn in one pass
    (:meth:`render_many`): per-column and per-object work is done for all views (poses x
    cameras) at once; per-pixel work runs as a few large NumPy calls over all views, or on
    large images per view and half image, spread over the cores.

    Args:
        width: Image width in pixels (any size >= 8).
        height: Image height in pixels (any size >= 8).

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> from oasis_torchrl.sim.world import World
        >>> scene = build_scene("rural", 0)
        >>> renderer = Renderer(96, 64)
        >>> renderer.prepare(scene)
        >>> frames = {name: np.zeros((64, 96, 3), np.uint8) for name in CAMERAS}
        >>> renderer.render(World(scene, 0.05).state, 0, frames)
        >>> int(frames["front"][0].mean()) > 0  # the sky
        True
    """

    def __init__(self, width: int, height: int) -> None:
        self.model = model = CameraModel(width, height)
        depths = model.row_depths()
        self._row_depths = depths.astype(np.float32)
        self._row_offsets = (model.horizon - np.arange(height) - 0.5).astype(np.float32)
        self._first_below = int(np.searchsorted(-depths, -np.inf, side="right"))
        self._first_ground = first_ground = int(np.searchsorted(-depths, -FAR, side="left"))
        self._ground_depths = ground_depths = depths[first_ground:]
        self._first_near_row = int(np.searchsorted(-ground_depths, -FAR_TEXTURE_DEPTH))
        self._samples = np.geomspace(ground_depths[-1], FAR, DEPTH_SAMPLES)[::-1].copy()
        self._row_samples = _interpolation_weights(self._samples, ground_depths)
        knots = np.arange(0, model.padded_width + 1, model.knot)
        self._knot_slopes = model.column_slopes(knots)
        self._knot_steps = np.arange(model.knot, dtype=np.float32)
        self._knot_fraction = np.arange(model.knot) / model.knot
        self._yaws = np.array([CAMERA_YAWS[name] for name in CAMERAS])
        self._index = np.zeros(0, dtype=np.uint8)
        self._parallel = width * height >= PARALLEL_PIXELS
        self._scene: Scene | None = None

    def prepare(self, scene: Scene) -> None:
        """Bake everything that depends on the scene: palettes, profiles, particles."""
        model = self.model
        self._scene = scene
        self._look = look = scene_look(scene.style)
        elevation = np.clip(self._row_offsets / (model.height / 2), 0.0, 1.0)
        sky_level = np.minimum(elevation**0.6 * SKY_LEVELS, SKY_LEVELS - 1).astype(np.uint8)
        levels = (np.arange(SKY_LEVELS) + 0.5) / SKY_LEVELS
        self._palettes = [
            _QuadPalette(build_palette(look, CAMERA_YAWS[name], levels)) for name in CAMERAS
        ]
        background = material("sky") + sky_level
        background[self._first_below :] = material("grass") + GROUND_BANDS - 1
        self._background = np.repeat(background[:, None], model.padded_width, axis=1)
        self._ground_bands = depth_bands(self._ground_depths, GROUND_BANDS, look.band_distance)
        self._ground_profiles = ground_profiles(scene).ravel()
        self._dashed_lines = dashed_lines(scene.style)
        self._obstacles = _ObstacleGeometry.of(scene)
        self._particles = _Particles(model, scene)
        logger.debug("renderer %dx%d ready for %r", model.width, model.height, scene.prompt)

    def render(self, car: VehicleState, frame: int, out: dict[str, np.ndarray]) -> None:
        """Draw every camera into ``out[name]`` (``uint8 [H, W, 3]``, written in place).

        ``frame`` (frames since the scene started) animates rain and snow.
        """
        self._check_images(out, (self.model.height, self.model.width, 3))
        self._render([car], [frame], {name: image[None] for name, image in out.items()})

    def render_many(
        self, cars: Sequence[VehicleState], frames: Sequence[int], out: dict[str, np.ndarray]
    ) -> None:
        """Draw every camera of several poses in one pass: ``out[name][k]`` (``out[name]`` is
        ``uint8 [len(cars), H, W, 3]``, written in place) shows ``cars[k]`` at ``frames[k]``.

        The same images as :meth:`render` of each pose in turn, at a fraction of the cost on
        small images (the per-call overhead is shared).

        Example:
            >>> from oasis_torchrl.sim.scene import build_scene
            >>> from oasis_torchrl.sim.world import World
            >>> world = World(build_scene("rural snow", 0), 0.05)
            >>> renderer = Renderer(96, 64)
            >>> renderer.prepare(world.scene)
            >>> poses = [world.state, world.state]
            >>> frames = {name: np.zeros((2, 64, 96, 3), np.uint8) for name in CAMERAS}
            >>> renderer.render_many(poses, [0, 5], frames)
            >>> bool(np.array_equal(frames["front"][0], frames["front"][1]))  # snow falls
            False
        """
        if len(frames) != len(cars):
            raise ValueError(f"frames must have one entry per car ({len(cars)}), got {len(frames)}")
        self._check_images(out, (len(cars), self.model.height, self.model.width, 3))
        self._render(cars, frames, out)

    def depth(self, car: VehicleState) -> dict[str, np.ndarray]:
        """Metric depth (along each camera axis, ``inf`` for sky) per camera, float32 [H, W]."""
        model = self.model
        buffer = np.empty((len(CAMERAS), model.height, model.padded_width), dtype=np.float32)
        buffer[...] = self._row_depths[:, None]
        self._draw(self._views([car]), buffer)
        return {
            name: np.ascontiguousarray(buffer[camera, :, : model.width])
            for camera, name in enumerate(CAMERAS)
        }

    def _render(
        self, cars: Sequence[VehicleState], frames: Sequence[int], out: dict[str, np.ndarray]
    ) -> None:
        """Draw the poses ``cars`` into ``out`` (checked by the caller)."""
        poses = len(cars)
        index = self._draw(self._views(cars), None)
        self._particles.draw(index, np.asarray(frames, dtype=np.float64))
        index = index.reshape(len(CAMERAS), poses, *index.shape[1:])
        width = self.model.width

        def convert(part: tuple[int, slice, slice]) -> None:
            camera, pose, rows = part
            indices = index[camera, pose, rows, :width]
            if not indices.flags.c_contiguous:  # padded rows: gather the visible columns
                scratch = _thread_array("pixels", indices.shape, np.uint8)
                np.copyto(scratch, indices)
                indices = scratch
            self._palettes[camera].convert(indices.reshape(-1), out[CAMERAS[camera]][pose, rows])

        _in_parallel(convert, self._rgb_parts(poses), self._parallel)

    def _check_images(self, out: dict[str, np.ndarray], shape: tuple[int, ...]) -> None:
        """Raise unless ``out`` holds a writable C-contiguous uint8 ``shape`` array per camera."""
        for name in CAMERAS:
            image = out.get(name)
            if not isinstance(image, np.ndarray):
                raise TypeError(f"out[{name!r}] must be a numpy array, got {type(image).__name__}")
            if (
                image.shape != shape
                or image.dtype != np.uint8
                or not image.flags.c_contiguous
                or not image.flags.writeable
            ):
                raise ValueError(
                    f"out[{name!r}] must be a writable C-contiguous uint8 array of shape "
                    f"{shape}, got {image.dtype} {image.shape}"
                )

    def _rgb_parts(self, poses: int) -> list[tuple[int, slice, slice]]:
        """``(camera, poses, rows)`` of the palette conversions: one per camera, or per camera,
        pose and half image when converting in parallel."""
        height = self.model.height
        if not self._parallel:
            return [(camera, slice(0, poses), slice(0, height)) for camera in range(len(CAMERAS))]
        middle = height // 8 * 4
        return [
            (camera, slice(pose, pose + 1), rows)
            for camera in range(len(CAMERAS))
            for pose in range(poses)
            for rows in (slice(0, middle), slice(middle, height))
            if rows.stop > rows.start
        ]

    def _require_scene(self) -> Scene:
        if self._scene is None:
            raise RuntimeError("Renderer.prepare(scene) must be called before rendering")
        return self._scene

    def _views(self, cars: Sequence[VehicleState]) -> _Views:
        """Where the cameras of every pose in ``cars`` are and where they look."""
        x = np.array([car.x + CAMERA_FORWARD * math.cos(car.heading) for car in cars])
        y = np.array([car.y + CAMERA_FORWARD * math.sin(car.heading) for car in cars])
        s, _ = self._require_scene().road.locate(x, y)
        heading = np.array([car.heading for car in cars])
        yaw = (heading - self._yaws[:, None]).ravel()
        cos, sin = np.cos(yaw), np.sin(yaw)
        cameras = len(CAMERAS)
        return _Views(
            np.tile(x, cameras),
            np.tile(y, cameras),
            np.tile(s, cameras),
            np.stack([cos, sin], 1),
            np.stack([sin, -cos], 1),
        )

    def _index_image(self, views: int) -> np.ndarray:
        """The palette-index image ``[views, rows, padded columns]`` (one buffer, grown to the
        most views drawn at once)."""
        model = self.model
        size = views * model.height * model.padded_width
        if self._index.size < size:
            self._index = np.zeros(size, dtype=np.uint8)
        return self._index[:size].reshape(views, model.height, model.padded_width)

    def _draw(self, views: _Views, depth: np.ndarray | None) -> np.ndarray:
        """Fill and return the index image (and ``depth`` if given) of every view."""
        index = self._index_image(views.x.size)
        s_samples, d_samples = self._ground_samples(views)
        ground = self._plan_ground(s_samples, d_samples)
        walls = [
            plan
            for layer in self._require_scene().roadside
            if (plan := self._plan_roadside(layer, s_samples, d_samples)) is not None
        ]

        def draw_part(part: _Part) -> None:
            np.copyto(index[part], self._background[part[1]])
            self._draw_ground_rows(ground, index, part)
            for plan in walls:
                self._draw_wall_rows(plan, index, part, depth)

        _in_parallel(draw_part, self._draw_parts(walls, views.x.size), self._parallel)
        self._draw_obstacles(views, walls, index, depth)
        return index

    def _draw_parts(self, walls: list[_WallPlan], views: int) -> list[_Part]:
        """All views in one part, or when drawing in parallel each view's rows split in two
        parts of about equal per-pixel work."""
        height = self.model.height
        if not self._parallel:
            return [(slice(0, views), slice(0, height))]
        parts = []
        for view in range(views):
            work = np.ones(height)
            work[self._first_ground :] += GROUND_WORK
            for plan in walls:
                work[plan.first_row[view] : plan.last_row[view]] += WALL_WORK
            middle = int(np.searchsorted(np.cumsum(work), work.sum() / 2))
            one = slice(view, view + 1)
            parts += [(one, slice(0, middle)), (one, slice(middle, height))]
        return parts

    def _ground_samples(self, views: _Views) -> tuple[np.ndarray, np.ndarray]:
        """Road coordinates ``(s, d)`` of the ground at the sample depths (far first) under the
        knot columns: ``[views, DEPTH_SAMPLES, knots]`` each."""
        ray_x = views.forward[:, None, 0] + self._knot_slopes * views.right[:, None, 0]
        ray_y = views.forward[:, None, 1] + self._knot_slopes * views.right[:, None, 1]
        x = views.x[:, None, None] + self._samples[:, None] * ray_x[:, None, :]
        y = views.y[:, None, None] + self._samples[:, None] * ray_y[:, None, :]
        return self._require_scene().road.locate(x, y)

    def _by_row(self, samples: np.ndarray) -> np.ndarray:
        """Values at the sample depths (axis -2) interpolated to every ground row (linear in
        depth along a knot ray, exact for a straight road)."""
        lower, upper, weight = self._row_samples
        weight = weight[:, None]
        return samples[..., lower, :] * (1.0 - weight) + samples[..., upper, :] * weight

    def _row_profiles(self, s_samples: np.ndarray, d_rows: np.ndarray) -> np.ndarray:
        """Per view and ground row, the first entry of its lateral profile: the variant for
        the dashes where the row crosses each dashed line, and the row's depth band."""
        style = self._require_scene().style
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
        return (variant * GROUND_BANDS + self._ground_bands) * TEXTURE_COLUMNS

    def _plan_ground(self, s_samples: np.ndarray, d_samples: np.ndarray) -> _GroundPlan:
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
        return _GroundPlan(columns[..., :-1, None], step[..., None])

    def _draw_ground_rows(self, plan: _GroundPlan, index: np.ndarray, part: _Part) -> None:
        """Look up the ground pixels of ``part`` in their profiles."""
        views, rows = part
        first = self._first_ground
        ground = slice(max(rows.start - first, 0), max(rows.stop - first, 0))
        if ground.stop <= ground.start:
            return
        start, step = plan.start[views, ground], plan.step[views, ground]
        texel = _thread_array("ground_texel", (*start.shape[:-1], self.model.knot), np.float32)
        gather = _thread_array("ground_gather", texel.shape, np.intp)
        np.multiply(step, self._knot_steps, out=texel)
        texel += start
        np.copyto(gather, texel, casting="unsafe")
        pixels = index[views, first + ground.start : first + ground.stop]
        np.take(self._ground_profiles, gather, out=pixels.reshape(gather.shape), mode="clip")

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

    def _plan_roadside(
        self, layer: RoadsideLayer, s_samples: np.ndarray, d_samples: np.ndarray
    ) -> _WallPlan | None:
        """Where one roadside layer stands in every view's columns (None: nowhere)."""
        model = self.model
        inverse, s, is_left = self._wall_columns(layer, s_samples, d_samples)
        present, height, variant = _segments_at(layer, s, is_left)
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
        bands = depth_bands(depth, OBJECT_BANDS, self._look.band_distance)
        along = np.floor(np.where(visible, s, 0.0) / ROADSIDE_TEXEL).astype(np.intp)
        first_material, second_material = _roadside_materials(layer.kind, along, variant, bands)
        return _WallPlan(
            first_row=first_row,
            last_row=last_row,
            texels_per_row=texels_per_row.astype(np.float32),
            top_texel=top_texel.astype(np.uint16),
            pattern=_ROW_PATTERNS[layer.kind],
            first_material=first_material,
            difference=first_material ^ second_material,
            see_through=bool(np.any(second_material == TRANSPARENT)),
            depth=depth.astype(np.float32),
            top=top,
        )

    def _draw_wall_rows(
        self, plan: _WallPlan, index: np.ndarray, part: _Part, depth: np.ndarray | None
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
        level = _thread_array("wall_level", shape, np.float32)
        np.multiply(self._row_offsets[rows, None], plan.texels_per_row[views, None], out=level)
        level += CAMERA_HEIGHT / ROADSIDE_TEXEL
        texel = _thread_array("wall_texel", shape, np.int16)
        np.copyto(texel, level, casting="unsafe")
        texel = texel.view(np.uint16)
        opaque = _thread_array("wall_opaque", shape, np.bool_)
        second = _thread_array("wall_second", shape, np.bool_)
        np.less(texel, plan.top_texel[views, None], out=opaque)
        if first_row.size > 1:  # the rows are the views' union: keep each view's own rows
            number = np.arange(rows.start, rows.stop)
            opaque &= ((number >= first_row[:, None]) & (number < last_row[:, None]))[..., None]
        pattern = plan.pattern
        if pattern.mask is not None:
            texel &= pattern.mask
            texel -= pattern.low
        np.less(texel, pattern.span, out=second)
        value = _thread_array("wall_value", shape, np.uint8)
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

    def _draw_obstacles(
        self,
        views: _Views,
        walls: list[_WallPlan],
        index: np.ndarray,
        depth: np.ndarray | None,
    ) -> None:
        """Rasterise every visible obstacle face as pixel runs, far to near per view."""
        faces = self._obstacles.visible_faces(views)
        if faces is None:
            return
        spans = _face_spans(faces, self.model, walls, self._look.band_distance)
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
        flat = np.repeat(first_flat, rows) + local * self.model.padded_width
        # Runs are ordered far to near; NumPy assigns repeated indices in order, so the last
        # (nearest) write wins, as in a painter's algorithm.
        index.reshape(-1)[flat] = self._obstacles.textures[texel]
        if depth is not None:
            depth.reshape(-1)[flat] = np.repeat(span_depth, rows)


def _interpolation_weights(
    samples: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(lower, upper, weight)``: linear interpolation at ``points`` of values given at
    ``samples`` (monotonic; points outside are clamped to the ends), weight on ``upper``."""
    descending = samples[0] > samples[-1]
    ascending = samples[::-1] if descending else samples
    upper = np.clip(np.searchsorted(ascending, points), 1, samples.size - 1)
    lower = upper - 1
    span = ascending[upper] - ascending[lower]
    weight = np.clip((points - ascending[lower]) / span, 0.0, 1.0)
    if descending:
        lower, upper = samples.size - 1 - lower, samples.size - 1 - upper
    return lower, upper, weight


@dataclass(frozen=True)
class _Faces:
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

    def clipped(self) -> _Faces:
        """The faces cut at the near plane (faces wholly behind it dropped)."""
        keep = (self.z0 >= NEAR) | (self.z1 >= NEAR)
        view, x0, z0, w0, x1, z1, w1, height, texture = (
            getattr(self, field.name)[keep] for field in fields(self)
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            cut0 = np.clip((NEAR - z0) / (z1 - z0), 0.0, 1.0)
            cut1 = np.clip((NEAR - z1) / (z0 - z1), 0.0, 1.0)
        behind0, behind1 = z0 < NEAR, z1 < NEAR
        return _Faces(
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


#: Box corners in (along, across) units of the half extents, counter-clockwise.
_BOX_CORNERS = np.array([[1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0]])


@dataclass(frozen=True)
class _ObstacleGeometry:
    """What rasterising needs of a scene's obstacles, computed once per scene: footprint
    corners (counter-clockwise), the next corner of each, heights and texture ids."""

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
    def of(cls, scene: Scene) -> _ObstacleGeometry:
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
            texture=_OBSTACLE_TEXTURE_START[obstacles.kind] + obstacles.variant,
            textures=obstacle_textures().ravel(),
        )

    def visible_faces(self, views: _Views) -> _Faces | None:
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
        return _Faces(
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


def _face_spans(
    faces: _Faces, model: CameraModel, walls: list[_WallPlan], band_distance: float
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
    texels = _OBSTACLE_TEXTURE_START[-1] * 64
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


class _Particles:
    """Rain streaks or snow flakes per camera, falling deterministically with the frame index."""

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


class _QuadPalette:
    """Palette lookup straight into packed RGB, without per-frame allocations.

    The 12 bytes of every 4 pixels ``p0..p3`` are three little-endian uint32 words, each a
    function of two neighbouring palette indices: ``(p0, p1)``, ``(p1, p2)``, ``(p2, p3)``. A
    65536-entry table per word turns the conversion into three gathers.

    Example:
        >>> palette = np.arange(768, dtype=np.uint16).reshape(256, 3).astype(np.uint8)
        >>> indices = np.array([0, 1, 2, 3, 255], dtype=np.uint8)
        >>> out = np.empty((5, 3), dtype=np.uint8)
        >>> _QuadPalette(palette).convert(indices, out)
        >>> bool(np.array_equal(out, palette[indices]))
        True
    """

    def __init__(self, palette: np.ndarray) -> None:
        self.palette = palette
        channels = palette.astype(np.uint32)
        first, second = np.arange(65536) & 255, np.arange(65536) >> 8
        red, green, blue = channels[:, 0], channels[:, 1], channels[:, 2]
        self.tables = np.stack(
            [
                red[first] | green[first] << 8 | blue[first] << 16 | red[second] << 24,
                green[first] | blue[first] << 8 | red[second] << 16 | green[second] << 24,
                blue[first] | red[second] << 8 | green[second] << 16 | blue[second] << 24,
            ]
        ).astype(np.uint32)

    def convert(self, indices: np.ndarray, out: np.ndarray) -> None:
        """Write the colours of ``indices`` (uint8, contiguous, 1-D) into ``out`` (uint8,
        contiguous, ``indices.size * 3`` bytes)."""
        quads = indices.size // 4
        flat = out.reshape(-1)
        if quads:
            pairs = _thread_array("quad_pairs", (3, quads), np.intp)
            words = _thread_array("quad_words", (3, quads), np.uint32)
            leading = indices[: 4 * quads].view(np.uint16)
            middle = indices[1 : 4 * quads - 1].view(np.uint16)
            np.copyto(pairs[0], leading[0::2])
            np.copyto(pairs[1], middle[0::2])
            np.copyto(pairs[2], leading[1::2])
            packed = flat[: 12 * quads].view(np.uint32).reshape(quads, 3)
            for word in range(3):
                np.take(self.tables[word], pairs[word], out=words[word], mode="clip")
                np.copyto(packed[:, word], words[word])
        tail = indices[4 * quads :]
        flat[12 * quads :] = self.palette[tail].reshape(-1)


#: Images at least this large (pixels per camera) are drawn by several threads.
PARALLEL_PIXELS = 200_000
#: Most threads the renderer spreads per-pixel work over.
MAX_WORKERS = 4
#: Relative per-pixel cost of ground and of each wall layer (a plain row costs 1), to split
#: each camera's rows into parts of equal work.
GROUND_WORK = 5.0
WALL_WORK = 12.0


@functools.cache
def _workers() -> ThreadPoolExecutor | None:
    """The shared pool that runs chunks (None on a single core)."""
    count = min(os.cpu_count() or 1, MAX_WORKERS)
    return ThreadPoolExecutor(count, thread_name_prefix="oasis-render") if count > 1 else None


def _in_parallel(function: Callable[[T], None], items: Sequence[T], parallel: bool) -> None:
    """Run ``function`` on every item, spread over the worker threads if ``parallel`` (NumPy
    releases the GIL inside its loops, so large independent parts of images run on separate
    cores; small ones are faster in one thread)."""
    workers = _workers() if parallel else None
    if workers is None or len(items) < 2:
        for item in items:
            function(item)
        return
    for _ in workers.map(function, items):
        pass


_scratch = threading.local()


def _thread_array(name: str, shape: tuple[int, ...], dtype: type) -> np.ndarray:
    """This thread's work array ``name`` of ``shape`` (a view of a buffer grown as needed, so
    per-pixel work allocates no frame-sized temporaries)."""
    size = math.prod(shape)
    buffer = getattr(_scratch, name, None)
    if buffer is None or buffer.size < size:
        buffer = np.empty(size, dtype=dtype)
        setattr(_scratch, name, buffer)
    return buffer[:size].reshape(shape)
