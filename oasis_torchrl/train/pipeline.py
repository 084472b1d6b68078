"""The main job in one call: record -> behaviour cloning -> PPO fine-tuning -> evaluation.

1. ``record``: autopilot demonstrations as a LeRobot dataset (one row per frame), with noise
   injected into the executed actions (:mod:`oasis_torchrl.train.demonstrations`);
2. ``bc``: behaviour cloning on it (the ``bc`` stage settings,
   :class:`~oasis_torchrl.config.BCSettings`),
   then ``dagger.rounds`` DAgger rounds: the clone drives ``dagger.episodes`` episodes labelled
   by the autopilot and is fine-tuned for ``dagger.steps`` on them and all the earlier data
   (:func:`~oasis_torchrl.train.stages.record_dagger_round`; the demonstrations themselves
   are never written to);
3. ``ppo``: PPO fine-tuning warm-started from the cloned policy (the ``ppo`` stage settings,
   :class:`~oasis_torchrl.config.PPOSettings`, with the shared ``env``);
4. ``eval``: the reference drivers, the shipped policies (``eval.pretrained``, by default every
   one the package ships), the cloned and the fine-tuned policy on the same fixed prompts and
   seeds (a fine-tuning that did not beat the clone is "not kept": no row of its own); the
   best learned policy's episodes go to rerun (``eval.rerun``, by default
   ``<output_dir>/eval.rrd``) and to a LeRobot dataset if ``eval.lerobot`` is set.

On an endpoint that sends frames only (the hosted service, a hosted-like server) there is no
autopilot: the demonstrations come from ``record.source`` (a saved or served policy, a LeRobot
dataset of a person's drives, or a folder of recordings in the reference format, imported), the
DAgger rounds are labelled by ``dagger.labeller`` (by default the demonstrating policy; none
after a dataset), behaviour cloning has no auxiliary loss, PPO a camera-only critic and the
frames-only motion reward, and the comparison reports returns
(:class:`~oasis_torchrl.train.plan.Demonstrators`). Without a source it stops at once, saying
what to pass.

The run is planned before its first stage (:class:`~oasis_torchrl.train.plan.RunPlan`: the
endpoint asked once, the demonstrators, every stage's settings and folders); each stage of
:mod:`oasis_torchrl.train.stages` takes its part and returns its product.

Every stage shows a progress bar. A stage whose output already exists is reused (delete the
folder to redo it), so re-running after an interruption continues where it stopped. Outputs under
``output_dir``: ``demos/`` (dataset), ``bc/round_<k>/policy/``, ``ppo/policy/`` (LeRobot policy
folders), ``bc/round_<k>/dagger/`` and ``bc/round_<k>/dataset/`` (round k's episodes, and the
data it cloned: the demonstrations and rounds 1 to k), ``ppo/checkpoints/`` (``latest.pt``, the
training state; ``best.pt``, the policy kept when PPO's evaluations select one), ``eval.rrd``,
``summary.json`` (paths, evaluations with their episodes, seconds per stage) and
``comparison.png`` (the evaluations as bars; the same comparison as a text table is
:meth:`PipelineResult.table`). Config: :class:`~oasis_torchrl.config.DemoConfig`.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from oasis_torchrl.config import save_config
from oasis_torchrl.drivers import pretrained_path
from oasis_torchrl.train.cards import hours, load_card
from oasis_torchrl.train.comparison import (
    PolicyRow,
    best_learned,
    comparison_rows,
    format_table,
    plot_comparison,
)
from oasis_torchrl.train.plan import plan_run
from oasis_torchrl.train.stage_seconds import STAGE_SECONDS, timed_stage
from oasis_torchrl.train.stages import (
    evaluate_and_record_best,
    gather_demonstrations,
    run_ppo,
    train_clone,
)

logger = logging.getLogger(__name__)

EVALUATION = "eval"
"""The final comparison's stage: timed, but not part of what the run took to learn."""

FINE_TUNE = "bc+ppo"


@dataclass
class PipelineResult:
    """Where the pipeline's outputs are, and the evaluation of every policy.

    Example:
        >>> result = run_pipeline(load_config("demo"))  # doctest: +SKIP
        >>> result.to_dict()["paths"]["recording"]  # doctest: +SKIP
        'outputs/demo/eval.rrd'
    """

    dataset: Path
    bc_policy: Path
    ppo_policy: Path
    ppo_checkpoint: Path
    recording: Path | None
    summary_path: Path
    plot_path: Path
    evaluations: dict[str, dict[str, Any]] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    fine_tune_kept: bool = True
    """Whether PPO fine-tuning beat the clone (else its row reads "not kept")."""
    cards: dict[str, dict[str, Any] | None] = field(default_factory=dict)
    """The evaluated shipped policies' card facts by row name (None: a policy without one)."""

    def rows(self) -> list[PolicyRow]:
        """The evaluations compared with the autopilot and the best constant action; a
        fine-tuning not kept is a "not kept" row."""
        rows = comparison_rows(self.evaluations, list(self.cards))
        return rows if self.fine_tune_kept else [*rows, PolicyRow.not_kept(FINE_TUNE)]

    def table(self) -> str:
        """The comparison as a text table, what learning took (with shipped policies), and where
        the files are."""
        total = sum(self.seconds.values())
        stages = ", ".join(f"{stage} {seconds:.0f} s" for stage, seconds in self.seconds.items())
        learned = self.learning_line()
        return (
            f"{format_table(self.rows())}\n"
            + (f"{learned}\n" if learned else "")
            + f"\n{total / 60:.1f} min ({stages}); summary {self.summary_path}, "
            + f"plot {self.plot_path}"
        )

    def learning_line(self) -> str | None:
        """One plain line: what this run learned in the minutes of its stages before the
        evaluation, and what the shipped policies took to train (from their cards); None without
        shipped policies.

        Example:
            >>> result = PipelineResult(*[Path()] * 7, seconds={"bc": 600.0},
            ...     evaluations={"constant:throttle=1.0": {"mean_distance": 100.0,
            ...     "collision_rate": 1.0, "episodes": 16}, "bc": {"mean_distance": 90.0,
            ...     "collision_rate": 0.5, "episodes": 16}},
            ...     cards={"pretrained:ppo-scratch": {"budget": "204,800 env steps",
            ...     "wall_seconds": 18000.0, "machine": "2 cores"}})
            >>> print(result.learning_line())
            This run learned in 10 min: bc drives 0.90x the best constant. The shipped policies \
took: pretrained:ppo-scratch 204,800 env steps, 5.0 h on 2 cores.
        """
        if not self.cards:
            return None
        own = [row for row in self.rows() if row.kind == "learned"]
        best = best_learned(own)
        minutes = sum(s for stage, s in self.seconds.items() if stage != EVALUATION) / 60
        learned = (
            f"{best.name} drives {best.vs_constant:.2f}x the best constant"
            if best is not None and best.vs_constant is not None
            else "no comparable policy"
        )
        took = "; ".join(
            f"{name} {card['budget']}, {hours(card['wall_seconds'])} on {card['machine']}"
            if card
            else f"{name} (no card)"
            for name, card in self.cards.items()
        )
        return (
            f"This run learned in {minutes:.0f} min: {learned}. The shipped policies took: {took}."
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``paths`` (str or None), ``evaluations`` and ``seconds`` per stage."""
        paths = {
            "dataset": self.dataset,
            "bc_policy": self.bc_policy,
            "ppo_policy": self.ppo_policy,
            "ppo_checkpoint": self.ppo_checkpoint,
            "recording": self.recording,
            "summary": self.summary_path,
            "plot": self.plot_path,
        }
        return {
            "paths": {name: None if path is None else str(path) for name, path in paths.items()},
            "evaluations": self.evaluations,
            "fine_tune_kept": self.fine_tune_kept,
            "seconds": self.seconds,
        }


def run_pipeline(cfg: DictConfig) -> PipelineResult:
    """Run record -> BC -> PPO fine-tuning -> evaluation as ``cfg`` (a
    :class:`~oasis_torchrl.config.DemoConfig`) says: its plan
    (:class:`~oasis_torchrl.train.plan.RunPlan`) first, then each stage on its part.

    Example:
        >>> result = run_pipeline(load_config("demo"))  # doctest: +SKIP
        >>> result.evaluations["bc+ppo"]["mean_distance"]  # doctest: +SKIP
    """
    plan = plan_run(cfg)
    save_config(plan.config, plan.output_dir / "config.yaml")
    seconds: dict[str, float] = {}
    totals = plan.output_dir / STAGE_SECONDS
    with timed_stage(seconds, "record", totals):
        dataset = gather_demonstrations(plan.record)
    with timed_stage(seconds, "bc", totals):
        bc_policy = train_clone(plan.clone)
    with timed_stage(seconds, "ppo", totals):
        ppo = run_ppo(plan.ppo)
    # A fine-tuning that kept its warm start left the clone: its row reads "not kept".
    fine_tune_kept = ppo.policy_frames > 0
    learned = {"bc": str(bc_policy)} | ({FINE_TUNE: str(ppo.policy_dir)} if fine_tune_kept else {})
    policies = {spec: spec for spec in (*plan.references, *plan.shipped)} | learned
    with timed_stage(seconds, EVALUATION):
        evaluations = evaluate_and_record_best(plan.eval, policies, list(plan.shipped))
        result = PipelineResult(
            dataset,
            bc_policy,
            ppo.policy_dir,
            ppo.checkpoint,
            plan.eval.recording,
            plan.output_dir / "summary.json",
            plan.output_dir / "comparison.png",
            evaluations,
            seconds,
            fine_tune_kept,
            {name: load_card(pretrained_path(name)) for name in plan.shipped},
        )
    write_summary(result, plan.eval.recorded)
    logger.info("pipeline done in %.0f s; summary: %s", sum(seconds.values()), result.summary_path)
    return result


def write_summary(result: PipelineResult, settings: DictConfig) -> None:
    """Write the result's ``summary.json`` and its comparison plot, titled with the evaluation
    ``settings`` (prompts, episodes, steps and seeds)."""
    result.summary_path.write_text(json.dumps(result.to_dict(), indent=2))
    seeds = ", ".join(str(seed) for seed in settings.seeds)
    title = (
        f"{', '.join(settings.prompts)}: {settings.episodes} episodes of up to "
        f"{settings.max_steps} steps per seed ({seeds})"
    )
    plot_comparison(result.rows(), result.plot_path, title)
