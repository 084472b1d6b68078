"""The style of a procedural scene, read from its prompt.

The prompt is read for keywords (case-insensitive; a word that starts with a keyword counts, so
``rainy``, ``snowy``, ``foggy``, ``nighttime``, ``highways`` match too):

============================  ===========  ====================================================
keyword                       sets         effect
============================  ===========  ====================================================
``urban``, ``city``,          layout       2-4 lanes with parking strips, sidewalks, buildings,
``cities``                                 parked cars, pedestrians, barriers, dense obstacles,
                                           tighter curves; speed cap 14 m/s
``highway``                   layout       3-4 wide lanes, hard shoulder, guard rails, tree
                                           lines, gentle curves, sparse stalled cars and
                                           barriers; speed cap 25 m/s
``rural``                     layout       2 lanes, fields, tree lines, more curves, sparse
                                           obstacles; speed cap 18 m/s
``night``                     lighting     dark sky, headlight falloff, lit windows
``sunset``                    lighting     orange sky, warm palette
``rain``                      weather      darker palette, grey sky, rain streaks
``snow``                      weather      white ground edges, pale sky, snow flakes
``fog``                       weather      strong distance fog
============================  ===========  ====================================================

The first layout keyword in the text wins. Without one, the layout is chosen from a hash of the
text, so any prompt gives a valid scene; without lighting or weather keywords it is a clear day.
Each layout fixes its cross-section, speed cap, curves and densities (:data:`LAYOUT_SPECS`); the
rest of the world is drawn from the seed (:mod:`oasis_torchrl.sim.scene`).
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass

import numpy as np

LAYOUTS = ("urban", "highway", "rural")
LIGHTINGS = ("day", "night", "sunset")
WEATHERS = ("clear", "rain", "snow", "fog")

_LAYOUT_WORDS = {
    "urban": "urban",
    "city": "urban",
    "cities": "urban",
    "highway": "highway",
    "rural": "rural",
}
_LIGHTING_WORDS = {"night": "night", "sunset": "sunset"}
_WEATHER_WORDS = {"rain": "rain", "snow": "snow", "fog": "fog"}


@dataclass(frozen=True, slots=True)
class LayoutSpec:
    """Everything a layout fixes: cross-section, speed, curves, obstacle and roadside density."""

    lanes: tuple[int, int]
    lane_width: float
    shoulder_width: float
    verge_width: float
    speed_limit: float
    dash: tuple[float, float]
    segment_length: tuple[float, float]
    max_curvature: float
    straight_probability: float
    max_heading: float
    event_gap: tuple[float, float]
    event_kinds: tuple[float, float, float]


LAYOUT_SPECS = {
    "urban": LayoutSpec(
        lanes=(2, 4),
        lane_width=3.2,
        shoulder_width=2.4,
        verge_width=3.5,
        speed_limit=14.0,
        dash=(3.0, 8.0),
        segment_length=(40.0, 140.0),
        max_curvature=1 / 45,
        straight_probability=0.4,
        max_heading=0.6,
        event_gap=(38.0, 35.0),
        event_kinds=(0.5, 0.3, 0.2),
    ),
    "highway": LayoutSpec(
        lanes=(3, 4),
        lane_width=3.6,
        shoulder_width=3.0,
        verge_width=4.0,
        speed_limit=25.0,
        dash=(4.0, 16.0),
        segment_length=(150.0, 500.0),
        max_curvature=1 / 600,
        straight_probability=0.35,
        max_heading=0.45,
        event_gap=(130.0, 220.0),
        event_kinds=(0.6, 0.4, 0.0),
    ),
    "rural": LayoutSpec(
        lanes=(2, 2),
        lane_width=3.3,
        shoulder_width=0.8,
        verge_width=3.0,
        speed_limit=18.0,
        dash=(3.0, 8.0),
        segment_length=(50.0, 200.0),
        max_curvature=1 / 80,
        straight_probability=0.25,
        max_heading=0.7,
        event_gap=(75.0, 120.0),
        event_kinds=(0.45, 0.25, 0.3),
    ),
}


@dataclass(frozen=True, slots=True)
class Style:
    """What a prompt asks for: layout, lighting, weather and the road's cross-section.

    Example:
        >>> style = parse_style("rainy city at night", np.random.default_rng(0))
        >>> (style.layout, style.lighting, style.weather)
        ('urban', 'night', 'rain')
        >>> style.lane_offset(0) < 0  # lane 0 is the rightmost one (+ is left)
        True
    """

    layout: str
    lighting: str
    weather: str
    lanes: int
    lane_width: float
    shoulder_width: float
    verge_width: float
    speed_limit: float
    dash_length: float
    dash_period: float

    @property
    def half_lanes_width(self) -> float:
        """Half the width of all lanes together (lane edge lines sit here)."""
        return self.lanes * self.lane_width / 2

    @property
    def road_half_width(self) -> float:
        """Half the width of the paved road surface: lanes plus shoulder."""
        return self.half_lanes_width + self.shoulder_width

    def lane_offset(self, lane: int) -> float:
        """Lateral offset of the centre of ``lane`` (0 = rightmost), + is left."""
        return -self.half_lanes_width + (lane + 0.5) * self.lane_width

    def nearest_lane(self, lateral: float) -> int:
        """The lane whose centre line is nearest lateral offset ``lateral`` (0 = rightmost)."""
        lane = math.floor((lateral + self.half_lanes_width) / self.lane_width)
        return min(max(lane, 0), self.lanes - 1)


def _keyword(words: list[str], table: dict[str, str]) -> str | None:
    """The value of the first word that starts with one of ``table``'s keys."""
    for word in words:
        for key, value in table.items():
            if word.startswith(key):
                return value
    return None


def _text_hash(text: str) -> int:
    """A stable integer hash of ``text`` (Python's ``hash`` is salted per process)."""
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:8], "little")


def parse_style(prompt: str, rng: np.random.Generator) -> Style:
    """Read layout, lighting and weather keywords from ``prompt``; draw the lane count.

    Example:
        >>> parse_style("HIGHWAY in fog", np.random.default_rng(1)).lanes in (3, 4)
        True
    """
    words = re.findall(r"[a-z]+", prompt.lower())
    layout = _keyword(words, _LAYOUT_WORDS)
    if layout is None:
        layout = LAYOUTS[_text_hash(prompt.strip().lower()) % len(LAYOUTS)]
    spec = LAYOUT_SPECS[layout]
    return Style(
        layout=layout,
        lighting=_keyword(words, _LIGHTING_WORDS) or "day",
        weather=_keyword(words, _WEATHER_WORDS) or "clear",
        lanes=int(rng.integers(spec.lanes[0], spec.lanes[1] + 1)),
        lane_width=spec.lane_width,
        shoulder_width=spec.shoulder_width,
        verge_width=spec.verge_width,
        speed_limit=spec.speed_limit,
        dash_length=spec.dash[0],
        dash_period=spec.dash[1],
    )
