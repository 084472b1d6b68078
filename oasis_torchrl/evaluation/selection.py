"""Which of two policies is better: differences between evaluation reports (paired by prompt
and episode seed where the endpoint honours seeds, else unpaired) and the selection rule that
PPO, behaviour cloning, the main job and ``oasis-torchrl eval`` share.

Reports are :meth:`~oasis_torchrl.evaluation.reports.EvalReport.to_dict` dicts.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any


def difference(treated: dict[str, Any], baseline: dict[str, Any]) -> dict[str, Any]:
    """``treated - baseline`` (two :meth:`EvalReport.to_dict` results): the paired distance
    difference where both had ground truth and seeds, else the unpaired (Welch) difference in
    mean return (a frames-only endpoint ignores seeds, so no episode pairs with another).

    Example:
        >>> from oasis_torchrl.evaluation.reports import EpisodeResult, EvalReport
        >>> def report(*returns):
        ...     runs = [EpisodeResult("urban", 0, math.nan, False, r, 9) for r in returns]
        ...     return EvalReport(runs, ground_truth=False).to_dict()
        >>> gain = difference(report(3.0, 5.0), report(1.0, 2.0, 3.0))
        >>> gain["mean"], round(gain["stderr"], 3), gain["metric"], gain["paired"]
        (2.0, 1.155, 'episode_return', False)
    """
    if treated.get("ground_truth", True) and baseline.get("ground_truth", True):
        return {**paired_difference(treated, baseline), "metric": "distance", "paired": True}
    return {
        **unpaired_difference(treated, baseline, "episode_return"),
        "metric": "episode_return",
        "paired": False,
    }


def unpaired_difference(
    treated: dict[str, Any], baseline: dict[str, Any], key: str
) -> dict[str, float]:
    """Difference in the mean of episode ``key`` and its Welch standard error
    ``sqrt(s1^2/n1 + s2^2/n2)``: no pairing of episodes assumed.

    Example:
        >>> def report(*values):
        ...     return {"per_episode": [{"episode_return": v} for v in values]}
        >>> unpaired_difference(report(2.0, 4.0), report(1.0, 1.0), "episode_return")
        {'mean': 2.0, 'stderr': 1.0, 'episodes': 4.0}
    """
    groups = [[float(e[key]) for e in report["per_episode"]] for report in (treated, baseline)]
    if min(len(values) for values in groups) < 2:
        raise ValueError(
            f"an unpaired difference needs at least 2 episodes on each side, got "
            f"{len(groups[0])} and {len(groups[1])}"
        )
    means = [sum(values) / len(values) for values in groups]
    variances = [
        sum((v - mean) ** 2 for v in values) / (len(values) - 1) / len(values)
        for values, mean in zip(groups, means, strict=True)
    ]
    return {
        "mean": means[0] - means[1],
        "stderr": math.sqrt(sum(variances)),
        "episodes": float(len(groups[0]) + len(groups[1])),
    }


def paired_difference(treated: dict[str, Any], baseline: dict[str, Any]) -> dict[str, float]:
    """Mean and standard error of the per-episode distance differences ``treated - baseline``
    (two :meth:`EvalReport.to_dict` results) over the episodes both ran, matched by prompt and
    episode seed.

    Example:
        >>> from oasis_torchrl.evaluation.reports import EpisodeResult, EvalReport
        >>> def report(*metres):
        ...     runs = [EpisodeResult("urban", i, d, False, 0.0, 9) for i, d in enumerate(metres)]
        ...     return EvalReport(runs).to_dict()
        >>> paired_difference(report(12.0, 25.0, 31.0), report(10.0, 20.0, 30.0))
        {'mean': 2.666..., 'stderr': 1.201..., 'episodes': 3.0}
    """
    before = {(e["prompt"], e["episode_seed"]): e["distance"] for e in baseline["per_episode"]}
    differences = [
        episode["distance"] - before[(episode["prompt"], episode["episode_seed"])]
        for episode in treated["per_episode"]
        if (episode["prompt"], episode["episode_seed"]) in before
    ]
    count = len(differences)
    if count < 2:
        raise ValueError(f"a paired difference needs at least 2 shared episodes, got {count}")
    mean = sum(differences) / count
    variance = sum((d - mean) ** 2 for d in differences) / (count - 1)
    return {"mean": mean, "stderr": math.sqrt(variance / count), "episodes": float(count)}


def selection_key(report: Mapping[str, Any]) -> str:
    """The aggregate a selection compares in an evaluation: the mean distance where the
    endpoint sent ground truth, else the mean return.

    >>> selection_key({"ground_truth": False})
    'mean_return'
    """
    return "mean_distance" if report.get("ground_truth", True) else "mean_return"


def selection_figure(report: Mapping[str, Any]) -> float:
    """What a selection compares in an evaluation: its :func:`selection_key` aggregate.

    >>> selection_figure({"mean_distance": float("nan"), "mean_return": 3.0, "ground_truth": False})
    3.0
    """
    return report[selection_key(report)]


def beats(candidate: dict[str, Any], incumbent: dict[str, Any] | None, margin: float) -> bool:
    """Whether an evaluation (:meth:`EvalReport.to_dict`) should replace ``incumbent``, the
    evaluation of the policy kept so far (None: none yet): with ``margin`` 0, any higher mean
    distance; otherwise a paired gain of more than ``margin`` standard errors over the episodes
    both ran (a gain within an evaluation's noise keeps the incumbent).

    Example:
        >>> from oasis_torchrl.evaluation.reports import EpisodeResult, EvalReport
        >>> incumbent = EvalReport([EpisodeResult("urban", i, 100.0 * i, False, 0.0, 9)
        ...                         for i in range(4)]).to_dict()
        >>> lucky = {**incumbent, "mean_distance": 160.0, "per_episode": [
        ...     {**e, "distance": e["distance"] + g}
        ...     for e, g in zip(incumbent["per_episode"], (-30.0, 40.0, -20.0, 50.0))]}
        >>> beats(lucky, incumbent, margin=0.0), beats(lucky, incumbent, margin=2.0)
        (True, False)
    """
    if incumbent is None:
        return True
    if not margin:
        return selection_figure(candidate) > selection_figure(incumbent)
    if len(incumbent["per_episode"]) < 2:
        raise ValueError(
            f"a selection margin ({margin} standard errors) needs at least 2 evaluation "
            f"episodes on the selection seeds, got {len(incumbent['per_episode'])}: raise "
            "eval.episodes or set eval.selection_margin=0"
        )
    gain = difference(candidate, incumbent)
    return gain["mean"] > margin * gain["stderr"]
