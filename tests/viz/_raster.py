"""Draws the top-down layers of a recording into a picture, the way rerun's 2D view does: thick
lines with round caps and joins, radii in scene units, layers in draw order, the view's bounds
fitted into the image (north of the picture is view ``-y``, ahead of the car)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw

from oasis_torchrl.viz.blueprint import BACKGROUND
from oasis_torchrl.viz.topdown import DRAW_ORDER, Window

from ._readback import Readback


def layer_at(readback: Readback, entity: str, frame: int) -> tuple[list, list, list]:
    """``(strips, radii, colours)`` of a LineStrips2D entity as last logged at or before
    ``frame``."""
    values = {}
    for component in ("strips", "radii", "colors"):
        frames, logged = readback.column(entity, f"LineStrips2D:{component}")
        before = [i for i, f in enumerate(frames) if f <= frame]
        values[component] = logged[before[-1]] if before else []
    return values["strips"], values["radii"] or [], values["colors"] or []


def _rgb(packed: int) -> tuple[int, int, int]:
    return (packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255


def draw(
    layers: dict[str, tuple[Sequence, Sequence, Sequence]],
    window: Window,
    pixels_per_metre: float,
) -> np.ndarray:
    """RGB ``[H, W, 3]`` of the window with the layers drawn over the view's background."""
    (x0, x1), (y0, y1) = window.x_range, window.y_range
    size = (round((x1 - x0) * pixels_per_metre), round((y1 - y0) * pixels_per_metre))
    image = Image.new("RGB", size, BACKGROUND)
    canvas = ImageDraw.Draw(image)
    for name in sorted(layers, key=DRAW_ORDER.__getitem__):
        strips, radii, colors = layers[name]
        for index, strip in enumerate(strips):
            radius = radii[min(index, len(radii) - 1)] * pixels_per_metre
            color = _rgb(colors[min(index, len(colors) - 1)])
            points = [((x - x0) * pixels_per_metre, (y - y0) * pixels_per_metre) for x, y in strip]
            if len(points) > 1:
                canvas.line(points, fill=color, width=max(1, round(2 * radius)), joint="curve")
            for px, py in (points[0], points[-1]):  # round caps
                canvas.ellipse((px - radius, py - radius, px + radius, py + radius), fill=color)
    return np.asarray(image)
