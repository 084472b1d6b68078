"""Tab titles as people read them: ``episode 3: collision at step 59``.

A row's tab is named after the episodes it shows (:class:`RowEpisodes`): each episode's number
(the same in its events and the summary) and, once it has ended, how and at which step. Side by
side, each policy's outcome is named after it. Every panel is titled with whose episodes it shows
(:func:`panel_title`): the policy's name, or the dataset's or robot's where there is no policy.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

LISTED = 2
"""A row with more episodes than this is titled by their range and the latest."""
_START = re.compile(r"episode (\d+) starts")
_END = re.compile(r"episode (\d+) ends: (.+?)(?: \(.*\))? after (\d+) steps")


@dataclass(frozen=True)
class EpisodeMark:
    """One episode of a row: its number and, once it has ended, its cause and steps.

    Example:
        >>> EpisodeMark(3, "collision", 59).describe(), EpisodeMark(4).describe()
        ('collision at step 59', 'running')
    """

    number: int
    cause: str | None = None
    steps: int = 0

    def describe(self) -> str:
        """``<cause> at step <steps>``, or ``running``."""
        return "running" if self.cause is None else f"{self.cause} at step {self.steps}"


@dataclass(frozen=True)
class RowEpisodes:
    """The episodes a row has shown: the first one's number, how many, and the latest (at most
    :data:`LISTED`), so a row that runs for hours keeps a bounded state.

    Example:
        >>> RowEpisodes().add(EpisodeMark(3)).ended(EpisodeMark(3, "time limit", 150)).latest
        (EpisodeMark(number=3, cause='time limit', steps=150),)
    """

    first: int = -1
    count: int = 0
    latest: tuple[EpisodeMark, ...] = ()

    def add(self, mark: EpisodeMark) -> RowEpisodes:
        """These episodes and a new one."""
        first = mark.number if self.count == 0 else self.first
        return RowEpisodes(first, self.count + 1, (*self.latest, mark)[-LISTED:])

    def ended(self, mark: EpisodeMark) -> RowEpisodes:
        """These episodes with the latest one's end."""
        return RowEpisodes(self.first, self.count, (*self.latest[:-1], mark))


def panel_title(owner: str, panel: str) -> str:
    """The title of a panel (a view) that shows ``owner``'s episodes: a policy's, a dataset's or
    a robot's name before the panel's own (the panel's alone where the owner is unnamed).

    Example:
        >>> panel_title("autopilot", "front"), panel_title("", "front")
        ('autopilot: front', 'front')
    """
    return f"{owner}: {panel}" if owner else panel


def tab_title(row: int, episodes: Mapping[str, RowEpisodes]) -> str:
    """The title of row ``row``'s tab from each policy's episodes there (a single policy is not
    named).

    Example:
        >>> ended = RowEpisodes().add(EpisodeMark(3, "collision", 59))
        >>> tab_title(0, {"env": ended})
        'episode 3: collision at step 59'
        >>> other = RowEpisodes().add(EpisodeMark(3, "time limit", 150))
        >>> tab_title(0, {"clone": ended, "autopilot": other})
        'episode 3: clone collision at step 59, autopilot time limit at step 150'
        >>> tab_title(5, {})
        'row 5'
    """
    known = {name: rows for name, rows in episodes.items() if rows.count}
    if not known:
        return f"row {row}"
    reference = next(iter(known.values()))
    if reference.count > LISTED:
        last = reference.latest[-1]
        numbers = f"episodes {reference.first}-{last.number} ({reference.count})"
        return f"{numbers}: {_outcomes(last.number, known)}"
    numbers = [mark.number for mark in reference.latest]
    return "; ".join(f"episode {number}: {_outcomes(number, known)}" for number in numbers)


def _outcomes(number: int, episodes: Mapping[str, RowEpisodes]) -> str:
    """Each policy's outcome of episode ``number`` (named when there are several)."""
    named = len(episodes) > 1
    parts = []
    for name, rows in episodes.items():
        mark = next((m for m in rows.latest if m.number == number), None)
        if mark is not None:
            parts.append(f"{name} {mark.describe()}" if named else mark.describe())
    return ", ".join(parts)


def episodes_of(events: Iterable[str]) -> RowEpisodes:
    """A row's episodes read back from its event texts, in order (a saved recording's, which
    ``oasis-torchrl view A.rrd B.rrd`` lays out again).

    Example:
        >>> events = ["episode 3 starts: 'urban', seed 7",
        ...           "episode 3 ends: collision (hit an obstacle) after 59 steps, return 1.000"]
        >>> episodes_of(events).latest
        (EpisodeMark(number=3, cause='collision', steps=59),)
    """
    episodes = RowEpisodes()
    for text in events:
        if start := _START.match(text):
            episodes = episodes.add(EpisodeMark(int(start[1])))
        elif (end := _END.match(text)) and episodes.count:
            episodes = episodes.ended(EpisodeMark(int(end[1]), end[2], int(end[3])))
    return episodes
