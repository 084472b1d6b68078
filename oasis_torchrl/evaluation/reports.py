"""Evaluation reports: each episode's result, their aggregates, and reports read back.

The distance is the embedded server's odometer at the episode's last step (NaN on servers
without ground truth); a collision is the episode ending *terminated*; the return sums the
rewards up to and including that step. A report of an endpoint that sends frames only says
``ground_truth: false`` and what its figures are (:data:`FRAMES_ONLY_NOTE`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

_PAIRED_KEYS = ("prompt", "episode_seed", "distance")
"""What every episode of a report holds for a paired comparison."""


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluation episode.

    Example:
        >>> EpisodeResult("urban", 7, distance=120.5, collided=True, episode_return=2.0, steps=60)
        EpisodeResult(prompt='urban', episode_seed=7, distance=120.5, collided=True, \
episode_return=2.0, steps=60, progress=None, likely_collision=False, reference_return=None)
    """

    prompt: str
    episode_seed: int
    distance: float
    collided: bool
    episode_return: float
    steps: int
    progress: float | None = None
    """The frames-only reward's progress term summed (None: not scored)."""
    likely_collision: bool = False
    """The frames-only reward terminated within the episode (a likely collision, from frames)."""
    reference_return: float | None = None
    """The return under the frames-only reward (None: not scored)."""


@dataclass
class EvalReport:
    """Episodes of an evaluation and their aggregates.

    Example:
        >>> report = EvalReport([EpisodeResult("urban", 1, 10.0, True, -5.0, 7),
        ...                      EpisodeResult("urban", 2, 30.0, False, 3.0, 20)])
        >>> report.mean_distance, report.collision_rate, report.mean_return
        (20.0, 0.5, -1.0)
    """

    episodes: list[EpisodeResult] = field(default_factory=list)
    ground_truth: bool = True
    """Whether the endpoint sent ground truth (distance, collisions) and honoured the seeds."""

    @property
    def mean_distance(self) -> float:
        """Mean distance before collision, metres (NaN without ground truth)."""
        return _mean([episode.distance for episode in self.episodes])

    @property
    def collision_rate(self) -> float:
        """Fraction of episodes that ended in a collision."""
        return _mean([float(episode.collided) for episode in self.episodes])

    @property
    def mean_return(self) -> float:
        """Mean episode return."""
        return _mean([episode.episode_return for episode in self.episodes])

    @property
    def mean_steps(self) -> float:
        """Mean episode length, steps (chunks)."""
        return _mean([float(episode.steps) for episode in self.episodes])

    @property
    def mean_progress(self) -> float | None:
        """Mean of the frames-only reward's progress term (None: not scored)."""
        progress = [episode.progress for episode in self.episodes]
        return None if None in progress else _mean(progress)

    @property
    def mean_reference_return(self) -> float | None:
        """Mean return under the frames-only reward (None: not scored)."""
        values = [episode.reference_return for episode in self.episodes]
        return None if None in values else _mean(values)

    @property
    def likely_collision_rate(self) -> float:
        """Fraction of episodes the frames-only reward ended (its likely collisions)."""
        return _mean([float(episode.likely_collision) for episode in self.episodes])

    def progress_figure(self) -> dict[str, str]:
        """The progress bar's figure: the distance with ground truth, else the return.

        >>> EvalReport([EpisodeResult("urban", 1, 10.0, True, -5.0, 7)]).progress_figure()
        {'distance': '10.0'}
        """
        if self.ground_truth and math.isfinite(self.mean_distance):
            return {"distance": f"{self.mean_distance:.1f}"}
        return {"return": f"{self.mean_return:.1f}"}

    def summary(self) -> dict[str, float]:
        """The aggregates (for loggers and progress bars; ``mean_progress`` where a frames-only
        reward was scored)."""
        progress, reference = self.mean_progress, self.mean_reference_return
        return {
            "mean_distance": self.mean_distance,
            "collision_rate": self.collision_rate,
            "mean_return": self.mean_return,
            "mean_steps": self.mean_steps,
            **({} if reference is None else {"mean_reference_return": reference}),
            **({} if progress is None else {"mean_progress": progress}),
            "likely_collision_rate": self.likely_collision_rate,
            "episodes": float(len(self.episodes)),
        }

    def per_prompt(self) -> dict[str, EvalReport]:
        """The episodes of each prompt (scene) as a report of their own, in the order the
        prompts first appear.

        Example:
            >>> report = EvalReport([EpisodeResult("urban", 1, 10.0, True, 0.0, 7),
            ...                      EpisodeResult("highway", 1, 30.0, False, 0.0, 20)])
            >>> {prompt: part.mean_distance for prompt, part in report.per_prompt().items()}
            {'urban': 10.0, 'highway': 30.0}
        """
        reports: dict[str, EvalReport] = {}
        for episode in self.episodes:
            part = reports.setdefault(episode.prompt, EvalReport(ground_truth=self.ground_truth))
            part.episodes.append(episode)
        return reports

    def to_dict(self, **extra: Any) -> dict[str, Any]:
        """``extra`` items, the aggregates (and, over several prompts, each prompt's under
        ``per_prompt``) and every episode, JSON-ready; a frames-only report says what its
        figures are."""
        labels = {"ground_truth": self.ground_truth}
        if not self.ground_truth:
            labels["note"] = FRAMES_ONLY_NOTE
        parts = self.per_prompt()
        scenes = {prompt: part.summary() for prompt, part in parts.items()}
        return {
            **extra,
            **labels,
            **self.summary(),
            **({"per_prompt": scenes} if len(parts) > 1 else {}),
            "per_episode": [asdict(e) for e in self.episodes],
        }

    def write_json(self, path: str | Path, **extra: Any) -> Path:
        """Write :meth:`to_dict` as JSON."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(**extra), indent=2))
        return path


FRAMES_ONLY_NOTE = (
    "frames only: no ground-truth distance or collisions (collision_rate counts the reward's "
    "likely-collision terminations); the endpoint ignores seeds, so episodes are not paired"
)


def load_report(path: str | Path) -> dict[str, Any]:
    """An evaluation report written by :meth:`EvalReport.write_json` (``oasis-torchrl eval
    output=...``), checked to hold what
    :func:`~oasis_torchrl.evaluation.selection.paired_difference` reads.

    Example:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> path = EvalReport([EpisodeResult("urban", 3, 50.0, True, 1.0, 9)]).write_json(
        ...     folder / "report.json")
        >>> load_report(path)["per_episode"][0]["distance"]
        50.0
        >>> _ = (folder / "other.json").write_text('{"mean_distance": 50.0}')
        >>> load_report(folder / "other.json")
        Traceback (most recent call last):
        ...
        ValueError: .../other.json is not an evaluation report: it has no per_episode list
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no evaluation report at {path}")
    try:
        report = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path} is not an evaluation report: not JSON ({error})") from None
    episodes = report.get("per_episode") if isinstance(report, dict) else None
    if not isinstance(episodes, list):
        raise ValueError(f"{path} is not an evaluation report: it has no per_episode list")
    for index, episode in enumerate(episodes):
        missing = [
            key for key in _PAIRED_KEYS if not isinstance(episode, dict) or key not in episode
        ]
        if missing:
            raise ValueError(
                f"{path} is not an evaluation report: episode {index} lacks {', '.join(missing)}"
            )
    return report


def _mean(values: Sequence[float]) -> float:
    return sum(values) / len(values) if values else math.nan
