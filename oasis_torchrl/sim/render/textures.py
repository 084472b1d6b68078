"""Procedural textures as palette indices: ground profiles, roadside walls, obstacle faces.

- Ground: lateral profiles of materials across the road (:data:`TEXTURE_COLUMN` metres per
  texel). The only along-road detail is the dashing of the lane lines; a row of the image
  crosses each line about once, so each row picks a profile variant: dashed line ``k`` drawn iff
  bit ``k`` is set, or the far variant (beyond :data:`FAR_TEXTURE_DEPTH`, where dashes would
  alias) with thin solid lines.
- Roadside walls: two materials per column along the wall, the second one where the wall's
  :class:`RowPattern` matches (windows, tree trunks, rail posts), in texels of
  :data:`ROADSIDE_TEXEL` metres.
- Obstacles: an 8x8 texture per kind and variant, for every depth band.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oasis_torchrl.sim.render.materials import (
    GROUND_BANDS,
    OBJECT_BANDS,
    TRANSPARENT,
    material,
)
from oasis_torchrl.sim.scene import (
    OBSTACLE_KINDS,
    OBSTACLE_VARIANTS,
    ROADSIDE_VARIANTS,
    Scene,
)
from oasis_torchrl.sim.style import Style

TEXTURE_COLUMN = 0.125
TEXTURE_COLUMNS = 1024
TEXTURE_HALF_WIDTH = TEXTURE_COLUMN * TEXTURE_COLUMNS / 2
FAR_TEXTURE_DEPTH = 45.0
LINE_HALF_WIDTH = 0.125
# Roadside walls: heights in texels of ROADSIDE_TEXEL metres, counted in uint8 (254 = 63.5 m).
ROADSIDE_TEXEL = 0.25


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


@dataclass(frozen=True)
class RowPattern:
    """Which wall heights (texel rows ``h``) use a column's second material:
    ``(h & mask) - low < span`` in uint16 arithmetic, or ``h < span`` without a mask.

    Example:
        >>> ROW_PATTERNS["trees"].span
        10
    """

    span: int
    mask: int | None = None
    low: int = 0


#: Windows 1.5-3.5 m up every 4 m floor; tree trunks below 2.5 m; rail posts below 0.5 m.
ROW_PATTERNS = {
    "building": RowPattern(8, mask=15, low=6),
    "trees": RowPattern(10),
    "rail": RowPattern(2),
}


def roadside_materials(
    kind: str, along: np.ndarray, variant: np.ndarray, band: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per column (``along``: texel column along the road): the wall's two palette indices.

    The second one is used where the kind's :class:`RowPattern` matches (windows, trunks,
    posts); :data:`TRANSPARENT` lets what is behind show through.

    Example:
        >>> first, second = roadside_materials("rail", np.arange(3), np.zeros(3, int),
        ...                                     np.zeros(3, int))
        >>> second.tolist() == [material("rail"), TRANSPARENT, TRANSPARENT]
        True
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
OBSTACLE_TEXTURE_START = np.cumsum([0] + [OBSTACLE_VARIANTS[kind] for kind in OBSTACLE_KINDS])


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
