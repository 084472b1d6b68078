"""Colours and light of a scene style, baked into one 256-colour palette per camera.

Lighting (day, sunset, night) sets the sky, the ambient light and the tint; weather sets the
sky's greyness, the fog distance and the ground (snow, wet asphalt); at night headlights light
mostly the front camera, fading with depth. Each palette entry is a material at one depth band,
lit and fogged, so light and fog cost nothing per pixel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.sim.render.materials import PALETTE, band_depths
from oasis_torchrl.sim.style import Style

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


def build_palette(look: Look, camera_yaw: float, sky_levels: np.ndarray) -> np.ndarray:
    """The 256-colour RGB palette ``[256, 3]`` of one camera (headlights light mostly the front
    camera).

    ``sky_levels`` are the gradient positions (0 horizon, 1 zenith) of the sky entries.

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> look = scene_look(build_scene("rural", 0).style)
        >>> build_palette(look, 0.0, np.linspace(0, 1, 16)).shape
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
        depth = band_depths(bands, look.band_distance)[:, None]
        light = look.ambient * look.tint + headlight * np.exp(-depth / HEADLIGHT_REACH)
        colour = look.emissive.get(name, look.colours[name] * light)
        fog = -np.expm1(-depth / look.fog_distance)
        palette[first : first + bands] = (1 - fog) * colour + fog * fog_colour
    return (np.clip(palette, 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
