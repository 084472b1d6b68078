"""Every plotted signal's fixed name and colour, and the plots (one unit each) they go in.

A signal is named by its last two entity components (``action/throttle``, ``reward/total``,
``truth/speed``), so it looks the same in every row, every episode, every recording and every
policy of a side-by-side recording. A signal this module does not list (a dataset's state
names, a custom reward term) still gets a fixed colour: one of :data:`SPARE_COLORS`, chosen by a
checksum of its name, never by the viewer.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import rerun as rr

Color = tuple[int, int, int]

LINE_WIDTH = 2.0
"""Width of every plotted line, in UI points."""


@dataclass(frozen=True)
class Signal:
    """How one signal is drawn: its legend name and colour."""

    name: str
    color: Color


SIGNALS: dict[str, Signal] = {
    "action/throttle": Signal("throttle", (0, 230, 118)),
    "action/steering": Signal("steering", (255, 235, 59)),
    "reward/total": Signal("reward", (240, 240, 240)),
    "reward/forward": Signal("forward", (76, 175, 80)),
    "reward/straightness_penalty": Signal("straightness penalty", (233, 30, 99)),
    "reward/heading": Signal("heading (summed steering)", (121, 85, 72)),
    "reward/progress_gained": Signal("progress", (139, 195, 74)),
    "reward/collision": Signal("collision penalty", (244, 67, 54)),
    "reward/lane_offset": Signal("lane offset penalty", (0, 188, 212)),
    "reward/clearance": Signal("clearance", (156, 39, 176)),
    "reward/collision_risk": Signal("collision risk (depth)", (255, 87, 34)),
    "reward/near_fraction": Signal("near fraction (depth)", (255, 193, 7)),
    "truth/obstacle_distance": Signal("distance to obstacle", (0, 150, 136)),
    "truth/speed": Signal("speed", (3, 169, 244)),
    "truth/lateral_offset": Signal("lateral offset", (205, 220, 57)),
    "collision/speed": Signal("collision", (255, 23, 68)),
    "collision/obstacle_distance": Signal("collision", (255, 23, 68)),
}
"""The known signals (the env's actions, every reward module's terms, the plotted truth, and
the collision markers: the speed and the distance ahead at the frame of a collision)."""

MARKERS = frozenset({"collision/speed", "collision/obstacle_distance"})
"""Signals drawn as points (a cross at a collision), not lines."""
COMPARED = (
    frozenset({"truth/speed", "truth/obstacle_distance", "truth/lateral_offset", "reward/total"})
    | MARKERS
)
"""Signals that policies side by side share a plot for: drawn in the policy's colour."""
MARKER_SIZE = 8.0

SPARE_COLORS: tuple[Color, ...] = (
    (141, 110, 99),
    (100, 181, 246),
    (174, 213, 129),
    (255, 138, 101),
    (186, 104, 200),
    (77, 208, 225),
    (255, 213, 79),
    (240, 98, 146),
)
"""Colours of signals not in :data:`SIGNALS`."""


def signal_key(path: str) -> str:
    """The palette key of an entity path: its last two components.

    Example:
        >>> signal_key("env/3/action/throttle")
        'action/throttle'
    """
    return "/".join(path.strip("/").split("/")[-2:])


def signal(path: str) -> Signal:
    """The fixed name and colour of the signal logged at ``path``.

    Example:
        >>> signal("env/0/truth/speed")
        Signal(name='speed', color=(3, 169, 244))
        >>> signal("episode/2/state/x") == signal("env/7/state/x")
        True
    """
    key = signal_key(path)
    known = SIGNALS.get(key)
    if known is not None:
        return known
    name = key.split("/")[-1]
    return Signal(name, SPARE_COLORS[zlib.crc32(key.encode()) % len(SPARE_COLORS)])


def series_style(path: str, policy: Policy | None = None) -> rr.SeriesLines | rr.SeriesPoints:
    """The ``SeriesLines`` (name, colour, width) or, for a marker, ``SeriesPoints`` to log
    statically at ``path``; with a ``policy``, a signal policies share a plot for
    (:data:`COMPARED`) takes the policy's name and colour.

    Example:
        >>> type(series_style("env/0/reward/total")).__name__
        'SeriesLines'
        >>> type(series_style("env/0/collision/speed")).__name__
        'SeriesPoints'
    """
    drawn = signal(path)
    key = signal_key(path)
    if policy is not None and key in COMPARED:
        drawn = Signal(f"{policy.name} {drawn.name}", policy.color)
    if key in MARKERS:
        return rr.SeriesPoints(
            colors=[drawn.color], names=[drawn.name], markers=["cross"], marker_sizes=[MARKER_SIZE]
        )
    return rr.SeriesLines(colors=[drawn.color], names=[drawn.name], widths=[LINE_WIDTH])


@dataclass(frozen=True)
class Plot:
    """One time-series plot: its title (with its one unit) and the signal keys it shows
    (``group/*`` for a whole group), less ``exclude``.

    Example:
        >>> PLOTS[0].shows("action/steering"), PLOTS[1].shows("reward/collision_risk")
        (True, False)
    """

    title: str
    include: tuple[str, ...]
    exclude: tuple[str, ...] = ()

    def shows(self, key: str) -> bool:
        """Whether the signal ``key`` belongs in this plot."""
        group = key.split("/")[0]
        wanted = key in self.include or f"{group}/*" in self.include
        return wanted and key not in self.exclude

    def contents(self) -> list[str]:
        """Blueprint contents, relative to a row's entity."""
        included = [key.replace("/*", "/**") for key in self.include]
        return [f"+ $origin/{key}" for key in included] + [f"- $origin/{k}" for k in self.exclude]


DEPTH_INTERNALS = ("reward/heading", "reward/near_fraction")
"""Depth-reward internals in other units than the reward's: logged, left out of the plots."""
PLOTS: tuple[Plot, ...] = (
    Plot("actions (-1 to 1)", ("action/*",)),
    Plot("state", ("state/*",)),
    Plot("reward", ("reward/*",), ("reward/collision_risk", *DEPTH_INTERNALS)),
    Plot("collision risk (depth, 0 to 1)", ("reward/collision_risk",)),
    Plot(
        "distance to obstacle ahead (m)",
        ("truth/obstacle_distance", "collision/obstacle_distance"),
    ),
    Plot("speed (m/s)", ("truth/speed", "collision/speed")),
    Plot("lateral offset (m)", ("truth/lateral_offset",)),
)
"""Every plot, in layout order; a row's layout holds those with at least one signal logged."""

POLICY_COLORS: tuple[Color, ...] = ((66, 133, 244), (255, 112, 67), (171, 71, 188), (0, 172, 193))
"""Colours of the policies of a recording, in order (repeating after the fourth): their bars in
the summary, their lines where they share a plot. No signal plotted beside them has one."""


@dataclass(frozen=True)
class Policy:
    """A policy as every view of a side-by-side recording shows it: its name and colour.

    Example:
        >>> Policy.at("autopilot", 0)
        Policy(name='autopilot', color=(66, 133, 244))
    """

    name: str
    color: Color

    @classmethod
    def at(cls, name: str, index: int) -> Policy:
        """The policy in column ``index`` of a recording."""
        return cls(name, POLICY_COLORS[index % len(POLICY_COLORS)])


SHARED_PLOTS: tuple[Plot, ...] = tuple(
    Plot(plot.title, tuple(sorted(key for key in COMPARED if plot.shows(key))))
    for plot in PLOTS
    if any(plot.shows(key) for key in COMPARED)
)
"""The plots that policies side by side draw on together, their :data:`COMPARED` signals only
(speed, distance to the obstacle ahead, lateral offset, reward).

Example:
    >>> [plot.title for plot in SHARED_PLOTS]
    ['reward', 'distance to obstacle ahead (m)', 'speed (m/s)', 'lateral offset (m)']
    >>> SHARED_PLOTS[2].include
    ('collision/speed', 'truth/speed')
"""
