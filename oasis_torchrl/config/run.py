"""The run section every training command shares: seed, output folder, progress bars, and for a
trainer its warm start and resume.

A command's config inherits it (:class:`RunSettings`: the main job; :class:`TrainingRun`:
``train ppo``, ``train bc``), so ``seed=1``, ``output_dir=...``, ``init_from=...`` and
``resume=latest`` mean one thing in each; a command only sets its own default output folder
(:func:`output_dir_option`). :func:`resume_point` is the one reading of ``resume``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from oasis_torchrl.options import option

LATEST = "latest"
"""``resume``'s spelling of the run's own last saved state."""


def output_dir_option(default: str) -> Any:
    """The ``output_dir`` field with a command's own default folder.

    Example:
        >>> output_dir_option("outputs/ppo").default
        'outputs/ppo'
    """
    return option(default, help="where the run writes: logs, checkpoints, its policy folder")


@dataclass
class RunSettings:
    """What every run has: a seed, an output folder, progress bars."""

    seed: int = option(0, help="seed of the run")
    output_dir: str = output_dir_option("outputs")
    progress: bool = option(True, help="tqdm progress bars")


@dataclass
class TrainingRun(RunSettings):
    """A training run: :class:`RunSettings`, a warm start and a resume."""

    init_from: str | None = option(
        None, help="warm start: a policy folder (BC, LeRobot) or a PPO checkpoint"
    )
    resume: str | None = option(
        None,
        help=f"continue a run stopped half way: '{LATEST}' (the last state saved in "
        "output_dir) or a saved state (PPO: a checkpoint file; BC: a checkpoints/last folder); "
        "null: start afresh",
    )


def resume_point(resume: str | None, latest: Path) -> Path | None:
    """Where ``resume`` continues from: ``latest`` (the run's own last saved state) for
    ``'latest'``, the given path otherwise; None: start afresh.

    Example:
        >>> resume_point("latest", Path("out/checkpoints/latest.pt"))
        PosixPath('out/checkpoints/latest.pt')
        >>> resume_point("elsewhere/last", Path("out/last")), resume_point(None, Path("out"))
        (PosixPath('elsewhere/last'), None)
    """
    if not resume:
        return None
    return latest if resume == LATEST else Path(resume)
