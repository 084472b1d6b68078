"""The summary tab: every episode's outcome and distance (or return, without ground truth) per
policy, so a person picks the episode to open.

Each ended episode is an :class:`EpisodeOutcome`; an :class:`EpisodeSummary` rewrites, as
static data, a table (``summary/table``, a markdown ``TextDocument``: one line per episode, one
column per policy giving how it ended, at which step, and the frames it has, a crash in bold and
the crashed policies in a column of their own) and a bar chart per policy (``summary/<policy>``,
one bar per episode at its number, in the policy's colour), the comparison the main job's
``comparison.png`` draws, episode by episode.
"""

from __future__ import annotations

import math
import threading
import warnings
from dataclasses import dataclass, field

import numpy as np
import rerun as rr

from oasis_torchrl.viz.palette import Color, Policy

SUMMARY_ROOT = "summary"
"""Root of the summary entities."""
TABLE = f"{SUMMARY_ROOT}/table"
"""The summary table (markdown)."""
CRASHES = ("collision", "likely collision")
"""Causes that are crashes."""


@dataclass(frozen=True)
class EpisodeOutcome:
    """How one logged episode ended.

    ``root`` is the entity root of its row (``env``, or the policy's root in a side-by-side
    recording); ``cause`` is one of ``collision``, ``likely collision``, ``terminated``,
    ``time limit`` or ``ended``; ``detail`` says more (``hit an obstacle``, the depth risk).
    ``actions`` are the episode's actions frame by frame (``[4 * steps, 2]``), what side-by-side
    recordings compare.

    Example:
        >>> outcome = EpisodeOutcome("env", 0, 0, "urban", 7, 0, 239, 59, "collision",
        ...                          "hit an obstacle", 118.2, 7.98)
        >>> outcome.figures()
        '59 steps, 118.2 m, return 7.980'
    """

    root: str
    row: int
    episode: int
    prompt: str | None
    seed: int | None
    start_frame: int
    end_frame: int
    steps: int
    cause: str
    detail: str
    distance: float
    episode_return: float
    actions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)), repr=False, compare=False)

    def figures(self) -> str:
        """The final figures: steps, distance (when known) and return."""
        distance = "" if math.isnan(self.distance) else f", {self.distance:.1f} m"
        return f"{self.steps} steps{distance}, return {self.episode_return:.3f}"

    def outcome(self) -> str:
        """The cause, with its detail when there is one."""
        return f"{self.cause} ({self.detail})" if self.detail else self.cause

    @property
    def crashed(self) -> bool:
        """Whether the episode ended in a crash (a collision, or the depth risk reaching 1)."""
        return self.cause in CRASHES

    def scene(self) -> tuple[int, int, str | None, int | None]:
        """What pairs episodes across policies: row, episode number, prompt and seed."""
        return (self.row, self.episode, self.prompt, self.seed)


class EpisodeSummary:
    """Collects episode outcomes (from any thread) and rewrites the summary entities.

    Args:
        recording: where the summary goes.
        roots: the policies' roots in column order (others are added as they appear).

    Example:
        >>> summary = EpisodeSummary(rr.RecordingStream("doc"))
        >>> summary.add(EpisodeOutcome("env", 0, 0, "urban", 7, 0, 239, 59, "collision",
        ...                            "hit an obstacle", 118.2, 7.98))
        >>> print(summary.table().splitlines()[-1].replace(" at step", "\\n  at step"))
        | 0 | 0 | urban | 7 | env | **collision (hit an obstacle)**
          at step 59, 118.2 m, frames 0-239 |
    """

    def __init__(self, recording: rr.RecordingStream, roots: tuple[str, ...] = ()) -> None:
        self.recording = recording
        self.roots = list(roots)
        self.outcomes: list[EpisodeOutcome] = []
        self._lock = threading.Lock()

    def add(self, outcome: EpisodeOutcome) -> None:
        """Record ``outcome`` and rewrite the table and the bar charts."""
        with self._lock:
            self.outcomes.append(outcome)
            if outcome.root not in self.roots:
                self.roots.append(outcome.root)
            self._write()

    def scenes(self) -> list[tuple[int, int, str | None, int | None]]:
        """The episodes' scenes, in table order (by episode number)."""
        return sorted({outcome.scene() for outcome in self.outcomes}, key=lambda s: (s[1], s[0]))

    def table(self) -> str:
        """The markdown table: one line per scene, one column per root."""
        cells = {(o.root, o.scene()): o for o in self.outcomes}
        lines = [
            "| episode | row | prompt | seed | crashed | " + " | ".join(self.roots) + " |",
            "|" + "---|" * (5 + len(self.roots)),
        ]
        for scene in self.scenes():
            outcomes = [cells.get((root, scene)) for root in self.roots]
            crashed = [o.root for o in outcomes if o is not None and o.crashed]
            row, episode, prompt, seed = scene
            results = " | ".join(_cell(outcome) for outcome in outcomes)
            lines.append(
                f"| {episode} | {row} | {prompt} | {seed} | {', '.join(crashed) or '-'} "
                f"| {results} |"
            )
        return "\n".join(lines)

    def _write(self) -> None:
        self.recording.log(
            TABLE, rr.TextDocument(self.table(), media_type="text/markdown"), static=True
        )
        cells = {(o.root, o.scene()): o for o in self.outcomes}
        scenes = self.scenes()
        episodes = np.array([scene[1] for scene in scenes], dtype=np.int64)
        for index, root in enumerate(self.roots):
            outcomes = [cells.get((root, scene)) for scene in scenes]
            values = np.array([_bar(outcome) for outcome in outcomes], dtype=np.float64)
            color = Policy.at(root, index).color
            self.recording.log(chart_path(root), bar_chart(values, color, episodes), static=True)


def bar_chart(values: np.ndarray, color: Color, episodes: np.ndarray) -> rr.BarChart:
    """One root's bar chart: a bar per episode, at its episode number.

    rerun's check that bar chart data is 1-D counts the dimensions longer than 1, so the chart
    of a single episode (every recording's first) would warn: that warning is ignored here.

    Example:
        >>> chart = bar_chart(np.array([118.2]), (255, 0, 0), np.array([0]))
        >>> type(chart).__name__
        'BarChart'
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Bar chart data should only be 1D")
        return rr.BarChart(values, color=color, abscissa=episodes)


def chart_path(root: str) -> str:
    """The bar chart entity of one root's episodes.

    Example:
        >>> chart_path("env")
        'summary/env'
    """
    return f"{SUMMARY_ROOT}/{root}"


def _bar(outcome: EpisodeOutcome | None) -> float:
    """A bar: the distance, else the return (no ground truth), else 0 (no such episode)."""
    if outcome is None:
        return 0.0
    return outcome.episode_return if math.isnan(outcome.distance) else outcome.distance


def _cell(outcome: EpisodeOutcome | None) -> str:
    """How one policy's episode ended (a crash in bold), at which step, its distance (or return)
    and the frames it has."""
    if outcome is None:
        return "-"
    how = f"**{outcome.outcome()}**" if outcome.crashed else outcome.outcome()
    figure = (
        f"return {outcome.episode_return:.2f}"
        if math.isnan(outcome.distance)
        else f"{outcome.distance:.1f} m"
    )
    frames = f"frames {outcome.start_frame}-{outcome.end_frame}"
    return f"{how} at step {outcome.steps}, {figure}, {frames}"
