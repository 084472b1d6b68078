"""The comparison a person reads at the end of a run: each evaluated policy's mean distance
(with its standard error over episodes), collision rate, and ratios to the autopilot and to the
best constant action, as a text table and as a matplotlib PNG. Evaluations on an endpoint that
sends frames only (``ground_truth: false``: no distance) are compared by their mean return
under the frames-only reward (the motion reward) instead, and their collisions are the reward's
likely-collision terminations.

Evaluations are :func:`oasis_torchrl.evaluation.EvalReport.to_dict` dicts (aggregates and
``per_episode`` results), keyed by policy name.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from oasis_torchrl.drivers.loading import AUTOPILOT, SCRIPTED
from oasis_torchrl.evaluation.selection import selection_figure

AUTOPILOT_COLOR = "0.25"
CONSTANT_COLOR = "0.65"
LEARNED_COLOR = "tab:blue"
SHIPPED_COLOR = "tab:green"
NOT_KEPT = "not kept"
"""The kind of a row whose policy a run did not keep (a fine-tuning that did not beat its warm
start): it has no figures of its own."""
LEARNED_KINDS = ("learned", "shipped")


@dataclass(frozen=True)
class PolicyRow:
    """One policy's line of the comparison.

    Example:
        >>> row = PolicyRow("bc", 200.0, 5.0, 0.25, 16, vs_autopilot=0.8, vs_constant=1.3)
        >>> row.kind
        'learned'
    """

    name: str
    mean_distance: float
    distance_stderr: float
    collision_rate: float
    episodes: int
    vs_autopilot: float | None = None
    vs_constant: float | None = None
    kind: str = "learned"
    """``autopilot``, ``constant``, ``learned`` (this run's), ``shipped`` (a shipped policy) or
    :data:`NOT_KEPT`."""
    unit: str = "m"
    """What ``mean_distance`` holds: metres, or ``return`` (frames only: the mean return)."""

    @classmethod
    def not_kept(cls, name: str) -> PolicyRow:
        """The row of a policy the run did not keep.

        Example:
            >>> PolicyRow.not_kept("bc+ppo").kind
            'not kept'
        """
        return cls(name, math.nan, math.nan, math.nan, 0, kind=NOT_KEPT)


FRAMES_ONLY_UNIT = "return"


def compared_value(evaluation: Mapping[str, Any]) -> tuple[str, str]:
    """The per-episode key an evaluation is compared by and its unit: the distance, or on
    frames alone (no ground truth) the return.

    Example:
        >>> compared_value({"ground_truth": False})
        ('episode_return', 'return')
    """
    if evaluation.get("ground_truth", True):
        return "distance", "m"
    return "episode_return", FRAMES_ONLY_UNIT


def distance_stderr(evaluation: Mapping[str, Any], key: str = "distance") -> float:
    """Standard error of the mean distance (or another per-episode ``key``) over the
    evaluation's episodes (NaN for fewer than two).

    Example:
        >>> distance_stderr({"per_episode": [{"distance": 10.0}, {"distance": 30.0}]})
        10.0
    """
    distances = [episode[key] for episode in evaluation.get("per_episode", [])]
    if len(distances) < 2:
        return math.nan
    mean = sum(distances) / len(distances)
    variance = sum((d - mean) ** 2 for d in distances) / (len(distances) - 1)
    return math.sqrt(variance / len(distances))


def comparison(
    evaluations: Mapping[str, Mapping[str, Any]],
    *,
    autopilot: str | None,
    constants: Sequence[str] = (),
    shipped: Sequence[str] = (),
) -> list[PolicyRow]:
    """The rows of ``evaluations``, in their order, with ratios to the ``autopilot`` entry and to
    the furthest-driving of the ``constants`` entries (either may be absent: no ratio); the
    ``shipped`` entries are shipped policies.

    Example:
        >>> evaluations = {
        ...     "autopilot": {"mean_distance": 300.0, "collision_rate": 0.0, "episodes": 16},
        ...     "constant": {"mean_distance": 150.0, "collision_rate": 0.9, "episodes": 16},
        ...     "bc": {"mean_distance": 240.0, "collision_rate": 0.3, "episodes": 16}}
        >>> rows = comparison(evaluations, autopilot="autopilot", constants=["constant"])
        >>> [(row.name, row.vs_autopilot, row.vs_constant) for row in rows][-1]
        ('bc', 0.8, 1.6)
    """
    expert = evaluations[autopilot]["mean_distance"] if autopilot in evaluations else None
    present = [name for name in constants if name in evaluations]
    best = max((evaluations[name]["mean_distance"] for name in present), default=None)
    rows = []
    for name, evaluation in evaluations.items():
        key, unit = compared_value(evaluation)
        distance = selection_figure(evaluation)
        kind = "autopilot" if name == autopilot else "constant" if name in present else "learned"
        kind = "shipped" if name in shipped else kind
        rows.append(
            PolicyRow(
                name,
                distance,
                distance_stderr(evaluation, key),
                evaluation["collision_rate"],
                int(evaluation["episodes"]),
                None if not expert or unit != "m" else distance / expert,
                None if not best or unit != "m" else distance / best,
                kind,
                unit,
            )
        )
    return rows


def comparison_rows(evaluations: dict[str, dict[str, Any]], shipped: list[str]) -> list[PolicyRow]:
    """The main job's evaluations as comparison rows: the autopilot, the scripted constants
    (``constant:...``) and the ``shipped`` policies named as such, the rest learned.

    Example:
        >>> evaluations = {"bc": {"mean_distance": 240.0, "collision_rate": 0.25, "episodes": 4}}
        >>> [(row.name, row.kind) for row in comparison_rows(evaluations, [])]
        [('bc', 'learned')]
    """
    constants = [name for name in evaluations if name.startswith(SCRIPTED)]
    return comparison(evaluations, autopilot=AUTOPILOT, constants=constants, shipped=shipped)


def best_learned(rows: Sequence[PolicyRow]) -> PolicyRow | None:
    """The learned or shipped row with the highest figure (None: there is none).

    Example:
        >>> rows = [PolicyRow("autopilot", 300.0, 2.0, 0.0, 16, kind="autopilot"),
        ...         PolicyRow("bc", 240.0, 12.5, 0.25, 16), PolicyRow.not_kept("bc+ppo")]
        >>> best_learned(rows).name
        'bc'
    """
    learned = [row for row in rows if row.kind in LEARNED_KINDS]
    return max(learned, key=lambda row: row.mean_distance, default=None)


def format_table(rows: Sequence[PolicyRow]) -> str:
    """A fixed-width text table of the rows.

    Example:
        >>> print(format_table([PolicyRow("bc", 240.0, 12.5, 0.25, 16, 0.8, 1.6)]))
        policy  mean distance   collision rate  vs autopilot  vs best constant
        bc      240.0 ± 12.5 m  0.25 (4/16)              80%             1.60x
    """
    frames_only = any(row.unit == FRAMES_ONLY_UNIT for row in rows)
    measure = "mean return (frames only)" if frames_only else "mean distance"
    header = ("policy", measure, "collision rate", "vs autopilot", "vs best constant")
    lines = [
        (row.name, NOT_KEPT, "", "", "")
        if row.kind == NOT_KEPT
        else (
            row.name,
            f"{row.mean_distance:.1f} ± {row.distance_stderr:.1f} {row.unit}",
            f"{row.collision_rate:.2f} ({round(row.collision_rate * row.episodes)}/{row.episodes})",
            "" if row.vs_autopilot is None else f"{row.vs_autopilot:.0%}",
            "" if row.vs_constant is None else f"{row.vs_constant:.2f}x",
        )
        for row in rows
    ]
    widths = [max(len(line[i]) for line in [header, *lines]) for i in range(len(header))]

    def render(cells: Sequence[str]) -> str:
        text = [cell.ljust(width) for cell, width in zip(cells[:3], widths, strict=False)]
        text += [cell.rjust(width) for cell, width in zip(cells[3:], widths[3:], strict=True)]
        return "  ".join(text).rstrip()

    return "\n".join(render(line) for line in [header, *lines])


def plot_comparison(rows: Sequence[PolicyRow], path: str | Path, title: str) -> Path:
    """A horizontal bar per policy (mean distance, standard-error whiskers, collision rate
    written beside it) as a PNG at ``path``.

    Example:
        >>> import tempfile
        >>> rows = [PolicyRow("autopilot", 300.0, 2.0, 0.0, 16, kind="autopilot"),
        ...         PolicyRow("bc", 240.0, 12.5, 0.25, 16)]
        >>> plot_comparison(rows, Path(tempfile.mkdtemp()) / "c.png", "demo").stat().st_size > 0
        True
    """
    from matplotlib.figure import Figure

    colors = {"autopilot": AUTOPILOT_COLOR, "constant": CONSTANT_COLOR, "shipped": SHIPPED_COLOR}
    figure = Figure(figsize=(8, 1.2 + 0.6 * len(rows)), layout="constrained")
    axes = figure.add_subplot()
    positions = list(range(len(rows)))[::-1]  # the first row on top
    axes.barh(
        positions,
        [0.0 if row.kind == NOT_KEPT else row.mean_distance for row in rows],
        xerr=[0.0 if math.isnan(row.distance_stderr) else row.distance_stderr for row in rows],
        color=[colors.get(row.kind, LEARNED_COLOR) for row in rows],
        capsize=3,
    )
    for position, row in zip(positions, rows, strict=True):
        if row.kind == NOT_KEPT:
            axes.annotate(f" {NOT_KEPT}", (0.0, position), va="center", fontsize=9)
            continue
        axes.annotate(
            f" {row.mean_distance:.1f} {row.unit}, collisions {row.collision_rate:.0%}",
            (row.mean_distance + (row.distance_stderr if row.distance_stderr > 0 else 0), position),
            va="center",
            fontsize=9,
        )
    axes.set_yticks(positions, [row.name for row in rows])
    frames_only = any(row.unit == FRAMES_ONLY_UNIT for row in rows)
    axes.set_xlabel(
        "mean return, reference reward (frames only), ± standard error"
        if frames_only
        else "mean distance before collision (m), ± standard error"
    )
    values = [row.mean_distance for row in rows if row.kind != NOT_KEPT]
    axes.set_xlim(1.35 * min([0.0, *values]), 1.35 * max([0.0, *values]) or 1.0)
    axes.set_title(title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=120)
    return path
