"""The renderer's materials and their places in the 256-entry palette.

Every material holds several palette entries, one per depth band (light and fog are baked into
each entry, see :mod:`~oasis_torchrl.sim.render.lighting`): ground materials
:data:`GROUND_BANDS`, the sky :data:`SKY_LEVELS` gradient levels, objects :data:`OBJECT_BANDS`.
"""

from __future__ import annotations

import math

import numpy as np

from oasis_torchrl.sim.render.camera import FAR
from oasis_torchrl.sim.scene import OBSTACLE_VARIANTS, ROADSIDE_VARIANTS

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
#: Marks see-through texels of roadside walls (never a palette entry).
TRANSPARENT = 255


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


PALETTE = _palette_layout()


def material(name: str) -> int:
    """First palette index of a material (its nearest depth band).

    Example:
        >>> material("grass")
        0
    """
    return PALETTE[name][0]


def depth_bands(depth: np.ndarray, bands: int, band_distance: float) -> np.ndarray:
    """Depth band of each depth: equal steps of ``1 - exp(-depth / band_distance)`` up to FAR.

    Example:
        >>> depth_bands(np.array([0.0, 50.0, np.inf]), 8, 100.0).tolist()
        [0, 3, 7]
    """
    scale = bands / -math.expm1(-FAR / band_distance)
    level = -np.expm1(-np.asarray(depth) / band_distance) * scale
    return np.minimum(level, bands - 1).astype(np.intp)


def band_depths(bands: int, band_distance: float) -> np.ndarray:
    """The representative depth of each band (the inverse of :func:`depth_bands` at centres).

    Example:
        >>> bool(np.all(depth_bands(band_depths(8, 100.0), 8, 100.0) == np.arange(8)))
        True
    """
    span = -math.expm1(-FAR / band_distance)
    return -band_distance * np.log1p(-(np.arange(bands) + 0.5) / bands * span)
