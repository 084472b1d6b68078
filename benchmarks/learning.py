"""Learning benchmark: do the policies really learn to drive in the world model?

On the embedded server, with the demo's training scenes (``DemoConfig.env.prompts``) and
resolution (96x64 frames, 64x96 policy images), evaluated on the "urban" prompt on fixed seeds,
one episode per env row of up to ``eval.max_steps`` chunks:

1. references: the autopilot (privileged expert) and constant actions (straight ahead, a sweep
   of throttles; the best one is "the best constant action");
2. behaviour cloning on autopilot demonstrations (recorded with noise injected into the
   executed actions): without DAgger, target at least 80% of the autopilot's mean distance
   before collision; then ``dagger.rounds`` DAgger rounds, target at least 90%;
3. PPO from scratch for ``--ppo-frames`` env steps, with a perception warm-up and replay (the
   ``ppo_scratch`` preset, ``configs/ppo_scratch.yaml``); targets: at least 1.5x the best
   constant action's mean distance with the policy chosen within the first
   ``--ppo-early-frames``, and 1.9x with the one chosen within the whole budget. On frames
   alone (``--ppo-overrides env.server.hosted=true warmup.frames=0 aux_replay.capacity=0``: the
   hosted-like server, the depth network's reward, a camera-only critic) both kept policies are
   judged on the embedded server with ground truth; target: at least 1.3x within the whole
   budget;
4. PPO fine-tuning of the cloned policy (or of ``--clone``, e.g. the shipped one); target:
   beats behaviour cloning by more than 2 standard errors of the paired per-episode difference
   (the same scenes, episode by episode). On frames alone (``--ppo-overrides
   env.server.hosted=true``) the kept policy is judged on the embedded server with ground truth;
   target: no worse than the clone beyond 2 standard errors;
5. held-out scenes: the references and every policy the run's other stages trained, on prompts
   no stage trained on (night, highway, rural, rain) and a seed no config uses, reported beside
   (no target).

Each PPO stage keeps the policy its periodic evaluations on ``--selection-seeds`` rate best
(early stopping), then evaluates that one on the evaluation seeds, which no choice has seen.

What runs is the main job's config (:class:`~oasis_torchrl.config.DemoConfig`) with the
``clone_256`` preset (``configs/clone_256.yaml``: demonstrations, BC steps, DAgger rounds; or
another ``--config``) and the benchmark's evaluation protocol (:data:`PROTOCOL`); the main job's
own flags (``--eval.episodes 16``, ``--record.episodes 64``) and ``KEY=VALUE`` overrides change
it, as on ``oasis-torchrl demo``.

Prints JSON (every evaluation with its episodes, the targets and whether they are met, the
exact settings and wall times) and writes it with a PNG (learning curves and the action scale
of the PPO stages) to ``--results``. Stages cache their outputs under ``--output-dir`` (a rerun
reuses finished stages). Budgets are stated in env steps: one env step is one chunk of 4
world-model frames (so frames = 4 x steps).

Usage: ``python benchmarks/learning.py [--output-dir outputs/learning] [--ppo-frames 204800]``
(several hours on 2 CPU cores). ``--stages`` runs some stages only, e.g. PPO from scratch in
one process (``--stages ppo_scratch``) and the rest in another; a last run with every stage then
assembles the report from the cache. A partial run writes what it ran, with the targets its
stages allow, to ``learning_<stages>.json`` and ``.png`` beside the full report. To rate only
the first budget of the full schedule, stop PPO from scratch there and keep the schedule of the
whole: ``--ppo-frames 102400 --ppo-overrides optim.anneal_frames=204800``.
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from _ranking import kendall_tau
from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.allocator import keep_batches_in_heap
from oasis_torchrl.config import DemoConfig, load_config
from oasis_torchrl.config.arguments import add_config_arguments, flag_values, split_overrides
from oasis_torchrl.config.presets import preset_file
from oasis_torchrl.config.scenes import LEARNING_HELD_OUT_PROMPTS, LEARNING_HELD_OUT_SEED
from oasis_torchrl.drivers.pretrained import resolve_pretrained
from oasis_torchrl.evaluation import paired_difference, selection_figure
from oasis_torchrl.train.pipeline import timed_stage
from oasis_torchrl.train.plan import EvaluationPlan, plan_run, ppo_config
from oasis_torchrl.train.ppo import evaluated_checkpoint_name
from oasis_torchrl.train.stages import (
    PPOStage,
    evaluate_all,
    gather_demonstrations,
    run_ppo,
    train_clone,
)

logger = logging.getLogger("benchmarks.learning")

CONSTANT_THROTTLES = (0.25, 0.5, 0.75, 1.0)
REFERENCES = {
    "autopilot": "autopilot",
    **{f"constant {t}": f"constant:throttle={t},steering=0.0" for t in CONSTANT_THROTTLES},
}
"""The reference policies: the privileged expert and straight drives at constant throttles."""
# PPO iterations between evaluations: 20 x 512 env steps (an evaluation of 32 episodes of up to
# 150 chunks costs about as many env steps as 10 iterations).
EVAL_EVERY = 20
CLONE_PRESET = "clone_256"
"""The preset of the clones' budgets (demonstrations, BC steps, DAgger rounds)."""
SCRATCH_PRESET = "ppo_scratch"
"""PPO from scratch's recipe over the ``PPOConfig`` defaults (its perception warm-up and
auxiliary replay; off with ``--ppo-overrides warmup.frames=0 aux_replay.capacity=0``)."""
PROTOCOL = {
    "output_dir": "outputs/learning",
    "env.max_steps": 150,
    "eval.max_steps": 150,
    "eval.episodes": 32,
    "eval.seeds": [1000],
    "eval.reference": [],
    "progress": False,
}
"""The benchmark's episodes and evaluation, over the main job's defaults and the clone preset
(flags and ``KEY=VALUE`` overrides come after it)."""
STAGES = ("references", "bc", "bc_dagger", "bc_ppo", "ppo_scratch", "held_out")
CLONE_STAGES = {"bc", "bc_dagger", "bc_ppo"}
COLORS = {
    "autopilot": "0.2",
    "best constant": "0.6",
    "bc": "tab:cyan",
    "bc + dagger": "tab:blue",
    "ppo (scratch)": "tab:red",
    "bc + ppo": "tab:green",
}
PPO_STAGES = {"ppo_scratch": "ppo (scratch)", "bc_ppo": "bc + ppo"}
ACTION_NAMES = ("throttle", "steering")
TARGETS = {
    "bc_over_autopilot": 0.8,
    "bc_dagger_over_autopilot": 0.9,
    "ppo_scratch_early_over_best_constant": 1.5,
    "ppo_scratch_over_best_constant": 1.9,
}
"""Each ratio's target (met when the ratio reaches it)."""
FRAMES_ONLY_TARGETS = {"ppo_scratch_over_best_constant": 1.3}
"""PPO from scratch on frames alone (judged on the embedded server): its one target; the ratio
within the smaller budget is reported without one."""


class StageCache:
    """Evaluations and stage wall times kept in a JSON file under the work folder, so a rerun
    (or a run split over processes with ``--stages``) reuses them: an evaluation is keyed by
    policy name, spec and evaluation settings; a stage's time is the first run's."""

    def __init__(self, path: Path) -> None:
        self.path = path
        saved = json.loads(path.read_text()) if path.exists() else {}
        self.evaluations: dict[str, dict[str, Any]] = saved.get("evaluations", {})
        self.seconds: dict[str, float] = saved.get("seconds", {})

    def evaluate(self, cfg: DictConfig, policies: dict[str, str]) -> dict[str, dict[str, Any]]:
        """``evaluate_all`` of each policy not evaluated yet with these settings."""
        settings = (
            f"prompts={list(cfg.eval.prompts)} episodes={cfg.eval.episodes} "
            f"seeds={list(cfg.eval.seeds)} steps={cfg.eval.max_steps}"
        )
        keys = {name: f"{name} {spec} {settings}" for name, spec in policies.items()}
        missing = {
            name: spec for name, spec in policies.items() if keys[name] not in self.evaluations
        }
        plan = EvaluationPlan.of(cfg)
        for name, spec in missing.items():  # saved one by one: a stopped run keeps each
            self.evaluations[keys[name]] = evaluate_all(plan, {name: spec}, record=True)[name]
            self._save()
        return {name: self.evaluations[keys[name]] for name in policies}

    @contextmanager
    def timed(self, stage: str) -> Iterator[None]:
        """Time a stage; only its first (not reused) run is kept."""
        run: dict[str, float] = {}
        with timed_stage(run, stage):
            yield
        if stage not in self.seconds:
            self.seconds[stage] = run[stage]
            self._save()

    def _save(self) -> None:
        # Re-read first: another process may have run other stages into the same file.
        saved = json.loads(self.path.read_text()) if self.path.exists() else {}
        saved.setdefault("evaluations", {}).update(self.evaluations)
        saved.setdefault("seconds", {}).update(self.seconds)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.write_text(json.dumps(saved, indent=2))


def benchmark_config(args: argparse.Namespace, overrides: list[str]) -> DictConfig:
    """The pipeline config of the benchmark: the main job's
    (:class:`~oasis_torchrl.config.DemoConfig`: its resolution, reward and settings) with
    ``--config`` (default the ``clone_256`` preset), :data:`PROTOCOL`, the main job's flags,
    then ``overrides``."""
    values = [*PROTOCOL.items(), *flag_values(args, DemoConfig)]
    return load_config("demo", overrides, file=args.config or CLONE_PRESET, values=values)


def held_out_config(cfg: DictConfig, episodes_per_prompt: int) -> DictConfig:
    """``cfg`` evaluating on the held-out prompts and seed instead."""
    scenes = {
        "prompts": list(LEARNING_HELD_OUT_PROMPTS),
        "episodes": episodes_per_prompt,
        "seeds": [LEARNING_HELD_OUT_SEED],
    }
    return OmegaConf.merge(cfg, {"eval": scenes})


def ppo_stage(
    cfg: DictConfig,
    init_from: Path | None,
    name: str,
    frames: int,
    args: argparse.Namespace,
) -> DictConfig:
    """A PPO stage of the benchmark: its own folder, budget and evaluations on the selection
    seeds every ``EVAL_EVERY`` batches, each evaluated policy kept (to choose within a smaller
    budget); fine-tuning (``init_from`` set) takes the demo's ``ppo`` overrides, PPO from
    scratch the :class:`~oasis_torchrl.config.PPOConfig` defaults and the ``ppo_scratch`` preset;
    ``args.ppo_overrides`` (``KEY=VALUE``) last."""
    fine_tune = init_from is not None
    stage = ppo_config(cfg, init_from, name, fine_tune=fine_tune)
    recipe = {} if fine_tune else scratch_recipe()
    evaluations = {
        "every": EVAL_EVERY,
        "episodes": cfg.eval.episodes,
        "selection_seeds": list(args.selection_seeds),
    }
    budget = {
        "collector": {"total_frames": frames},
        "eval": evaluations,
        "checkpoint": {"keep_evaluated": True},
    }
    return OmegaConf.merge(stage, recipe, budget, OmegaConf.from_dotlist(args.ppo_overrides))


def scratch_recipe() -> DictConfig:
    """The ``ppo_scratch`` preset's settings (its budget is the stage's own)."""
    return OmegaConf.load(preset_file(SCRATCH_PRESET))


def chosen_within(history: Sequence[dict[str, Any]], budget: int) -> dict[str, Any]:
    """The periodic evaluation (on the selection seeds) that rates best among the policies
    trained for at most ``budget`` env steps (the first of equals, as the trainer keeps with
    ``eval.selection_margin`` 0, the default PPO from scratch runs with): by distance, or by
    return where the PPO stage ran on a frames-only endpoint."""
    *periodic, _ = history
    within = [entry for entry in periodic if entry["policy_frames"] <= budget]
    if not within:
        raise ValueError(f"no PPO evaluation within {budget} env steps")
    return max(within, key=selection_figure)


def build_parser() -> argparse.ArgumentParser:
    """The benchmark's flags, and the main job's settings (``--config``, flags, overrides)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("benchmarks/results"))
    parser.add_argument(
        "--selection-seeds",
        type=int,
        nargs="+",
        default=[2000],
        help="seeds of PPO's periodic evaluations, which pick the policy each PPO stage keeps",
    )
    parser.add_argument("--held-out-episodes", type=int, default=8, help="per held-out prompt")
    parser.add_argument(
        "--ppo-frames", type=int, default=204800, help="PPO from scratch, env steps"
    )
    parser.add_argument(
        "--ppo-early-frames",
        type=int,
        default=102400,
        help="the smaller budget PPO from scratch is also rated within",
    )
    parser.add_argument(
        "--stages",
        nargs="+",
        choices=STAGES,
        default=list(STAGES),
        help="run only these stages (each caches under --output-dir; the report needs all)",
    )
    parser.add_argument("--finetune-frames", type=int, default=20480, help="BC + PPO, env steps")
    parser.add_argument(
        "--clone",
        help="the policy the bc_ppo stage fine-tunes (a folder or pretrained:NAME, e.g. "
        "pretrained:clone with --config pretrained_clone) instead of the run's own clone",
    )
    parser.add_argument(
        "--ppo-overrides",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="PPO settings of both PPO stages, e.g. ray.enabled=true (collection on two Ray "
        "workers, each with its own embedded server)",
    )
    add_config_arguments(parser, DemoConfig)  # the main job's settings: --config, flags
    return parser


def parse_arguments(argv: list[str] | None = None) -> tuple[argparse.Namespace, list[str]]:
    """The parsed flags and the ``KEY=VALUE`` overrides of ``argv`` (default: the process's)."""
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    overrides, unknown = split_overrides(extra)
    if unknown:
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    if args.clone and {"bc", "bc_dagger"} & set(args.stages):
        parser.error("--clone replaces the run's own clone: leave bc and bc_dagger out of --stages")
    return args, overrides


def main() -> None:
    args, overrides = parse_arguments()
    # force: LeRobot's import checks log first, which gives the root logger a WARNING handler.
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", force=True)
    keep_batches_in_heap()  # as the oasis-torchrl command does

    cfg = benchmark_config(args, overrides)
    work = Path(cfg.output_dir)
    cache = StageCache(work / "stages.json")
    results = run_stages(args, cfg, cache)
    settings = {
        "settings": {
            "results": str(args.results),
            "selection_seeds": args.selection_seeds,
            "held_out_episodes": args.held_out_episodes,
            "ppo_frames": args.ppo_frames,
            "ppo_early_frames": args.ppo_early_frames,
            "stages": args.stages,
            "finetune_frames": args.finetune_frames,
            "clone": args.clone,
            "ppo_overrides": args.ppo_overrides,
            "overrides": overrides,
            "scratch_recipe": OmegaConf.to_container(scratch_recipe()),
        },
        "config": OmegaConf.to_container(cfg),
    }
    # A partial run (e.g. one stage on its own) leaves what it ran beside the full report.
    ran = [stage for stage in STAGES if stage in results]
    name = "learning" if ran == list(STAGES) else f"learning_{'_'.join(ran)}"
    report = {**settings, **summarise(results), "seconds": cache.seconds}
    write_json(args.results / f"{name}.json", report)
    plot_report(report, scale_curves(work, results), args.results / f"{name}.png")
    if name != "learning":
        logger.info("ran %s; the full report needs every stage", ran)


def run_stages(args: argparse.Namespace, cfg: DictConfig, cache: StageCache) -> dict[str, Any]:
    """Run (or reuse) the stages of ``args.stages``; their results, by stage, in stage order."""
    stages = set(args.stages)
    work = Path(cfg.output_dir)
    results: dict[str, Any] = {}
    trained: dict[str, str] = {}
    if "references" in stages:
        with cache.timed("references"):
            results["references"] = cache.evaluate(cfg, REFERENCES)
    if args.clone:  # a given clone (e.g. the shipped one) in place of the run's own
        dagger_policy = Path(resolve_pretrained(args.clone))
        trained["bc_dagger"] = str(dagger_policy)
    elif stages & CLONE_STAGES:
        plan = plan_run(cfg)
        with cache.timed("record"):
            gather_demonstrations(plan.record)
        with cache.timed("bc"):
            dagger_policy = train_clone(plan.clone)
        trained["bc"] = str(plan.clone[0].policy)
        trained["bc_dagger"] = str(dagger_policy)
    for stage in ("bc", "bc_dagger"):
        if stage in stages:
            results[stage] = cache.evaluate(cfg, {stage: trained[stage]})[stage]
    if "bc_ppo" in stages:
        with cache.timed("bc_ppo"):
            finetune = run_ppo(ppo_stage(cfg, dagger_policy, "bc_ppo", args.finetune_frames, args))
            history = finetune.history
        trained["bc_ppo"] = str(work / "bc_ppo" / "policy")
        results["bc_ppo"] = history
        results["bc_ppo_start"] = cache.evaluate(cfg, {"bc_dagger": trained["bc_dagger"]})
        if not history[-1].get("ground_truth", True):  # judged with ground truth, as below
            results["bc_ppo_final"] = cache.evaluate(cfg, {"bc_ppo": trained["bc_ppo"]})["bc_ppo"]
            agreement = selection_agreement(cfg, cache, args, finetune)
            results["bc_ppo_selection"] = agreement
    if "ppo_scratch" in stages:
        with cache.timed("ppo_scratch"):
            scratch = run_ppo(ppo_stage(cfg, None, "ppo_scratch", args.ppo_frames, args))
            history = scratch.history
        trained["ppo_scratch"] = str(work / "ppo_scratch" / "policy")
        early = chosen_within(history, args.ppo_early_frames)
        checkpoints = work / "ppo_scratch" / "checkpoints"
        trained["ppo_scratch_early"] = str(checkpoints / evaluated_checkpoint_name(early["frames"]))
        results["ppo_scratch"] = history
        if not history[-1].get("ground_truth", True):
            # A frames-only PPO stage's own evaluations have no distance: its kept policy is
            # judged here, on the embedded server with ground truth, as the early one is.
            final = cache.evaluate(cfg, {"ppo_scratch": trained["ppo_scratch"]})
            results["ppo_scratch_final"] = final["ppo_scratch"]
            agreement = selection_agreement(cfg, cache, args, scratch)
            results["ppo_scratch_selection"] = agreement
        results["ppo_scratch_early"] = {
            "policy_frames": early["policy_frames"],
            **cache.evaluate(cfg, {"ppo_scratch_early": trained["ppo_scratch_early"]})[
                "ppo_scratch_early"
            ],
        }
    if "held_out" in stages:
        with cache.timed("held_out"):
            policies = {"autopilot": "autopilot", "constant 1.0": REFERENCES["constant 1.0"]}
            held_out = held_out_config(cfg, args.held_out_episodes)
            results["held_out"] = cache.evaluate(held_out, {**policies, **trained})
    return results


def selection_agreement(
    cfg: DictConfig,
    cache: StageCache,
    args: argparse.Namespace,
    stage: PPOStage,
) -> dict[str, Any]:
    """Whether a frames-only PPO stage's selection (by return under the frames-only reward)
    agrees with ground truth: every periodically evaluated policy driven again on the selection
    seeds on the embedded server, ranked by mean distance against its frames-only return
    (Kendall's tau), and the ground-truth distance of the policy the stage kept beside the best
    one's."""
    checkpoints = stage.checkpoint.parent
    *periodic, _ = stage.history
    specs = {
        f"{checkpoints.parent.name} at {entry['frames']}": str(
            checkpoints / evaluated_checkpoint_name(entry["frames"])
        )
        for entry in periodic
    }
    on_seeds = OmegaConf.merge(cfg, {"eval": {"seeds": list(args.selection_seeds)}})
    judged = cache.evaluate(on_seeds, specs)
    rows = [
        {
            "frames": entry["frames"],
            "frames_only_return": entry["mean_return"],
            "mean_distance": judged[name]["mean_distance"],
        }
        for name, entry in zip(specs, periodic, strict=True)
    ]
    kept = next(row for row in rows if row["frames"] == stage.policy_frames)
    best = max(rows, key=lambda row: row["mean_distance"])
    returns = [row["frames_only_return"] for row in rows]
    return {
        "kendall_tau": kendall_tau(returns, [row["mean_distance"] for row in rows]),
        "kept_frames": kept["frames"],
        "kept_distance": kept["mean_distance"],
        "best_frames": best["frames"],
        "best_distance": best["mean_distance"],
        "checkpoints": rows,
    }


def best_constant(references: dict[str, dict[str, Any]]) -> str:
    """The name of the constant action that drives furthest."""
    constants = [name for name in REFERENCES if name.startswith("constant")]
    return max(constants, key=lambda name: references[name]["mean_distance"])


def summarise(results: dict[str, Any]) -> dict[str, Any]:
    """The stages' results with the best constant action and every target their stages allow
    (each ratio, and whether it is met)."""
    report = dict(results)
    ratios: dict[str, float] = {}
    if "references" in results:
        references = results["references"]
        report["best_constant"] = best_constant(references)
        autopilot = references["autopilot"]["mean_distance"]
        constant = references[report["best_constant"]]["mean_distance"]
        for stage in ("bc", "bc_dagger"):
            if stage in results:
                ratios[f"{stage}_over_autopilot"] = results[stage]["mean_distance"] / autopilot
        if "ppo_scratch" in results:
            early = results["ppo_scratch_early"]["mean_distance"]
            ratios["ppo_scratch_early_over_best_constant"] = early / constant
            final = results.get("ppo_scratch_final", results["ppo_scratch"][-1])["mean_distance"]
            ratios["ppo_scratch_over_best_constant"] = final / constant
    goals = dict(TARGETS)
    if "ppo_scratch_final" in results:  # the PPO stage trained on frames alone
        goals = {name: goal for name, goal in goals.items() if not name.startswith("ppo_scratch")}
        goals.update(FRAMES_ONLY_TARGETS)
    targets: dict[str, dict[str, Any]] = {}
    for name, ratio in ratios.items():
        goal = goals.get(name)
        targets[name] = {
            "value": ratio,
            "target": goal,
            "met": None if goal is None else ratio >= goal,
        }
    for name, target in targets.items():  # a run shorter than a budget is rated on what it ran
        if name.startswith("ppo_scratch"):
            target["env_steps_run"] = results["ppo_scratch"][-1]["frames"]
    if "bc_ppo" in results:
        start = results["bc_ppo_start"]["bc_dagger"]
        if "bc_ppo_final" in results:  # fine-tuned on frames alone: it must keep the clone's
            difference = paired_difference(results["bc_ppo_final"], start)
            met = difference["mean"] >= -2 * difference["stderr"]
            targets["bc_ppo_minus_bc"] = {**difference, "target": ">= -2 stderr", "met": met}
        else:
            difference = paired_difference(results["bc_ppo"][-1], start)
            met = difference["mean"] > 2 * difference["stderr"]
            targets["bc_ppo_minus_bc"] = {**difference, "target": "> 2 stderr", "met": met}
    report["targets"] = targets
    return report


def scale_curves(work: Path, results: dict[str, Any]) -> dict[str, dict[str, list[list[float]]]]:
    """Each PPO stage's action scale per action number (``[env steps, scale]`` pairs) from its
    training log."""
    curves: dict[str, dict[str, list[list[float]]]] = {}
    for stage, name in PPO_STAGES.items():
        folder = work / stage / "logs" / "ppo" / "scalars" / "policy"
        if stage not in results or not folder.is_dir():
            continue
        curves[name] = {
            action: [[float(step), float(value)] for step, value in csv.reader(path.open())]
            for action in ACTION_NAMES
            if (path := folder / f"scale_{action}.csv").exists()
        }
    return curves


def plot_report(
    report: dict[str, Any], scales: dict[str, dict[str, list[list[float]]]], path: Path
) -> None:
    """Two panels: the PPO stages' distance curves on the selection seeds against the levels of
    the references and the clones on the evaluation seeds (each kept PPO policy as a marker at
    its env steps); and the PPO stages' action scale per action number."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10, 8), layout="constrained")
    distances, scale_axes = figure.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    levels: dict[str, float] = {}
    legend_x = 1.01  # further right when a return axis sits on the right
    if "references" in report:
        references = report["references"]
        levels["autopilot"] = references["autopilot"]["mean_distance"]
        levels["best constant"] = references[report["best_constant"]]["mean_distance"]
    for stage, name in (("bc", "bc"), ("bc_dagger", "bc + dagger")):
        if stage in report:
            levels[name] = report[stage]["mean_distance"]
    for name, level in levels.items():
        distances.axhline(level, color=COLORS[name], linestyle="--", label=f"{name}: {level:.0f} m")
    for stage, name in PPO_STAGES.items():
        if stage not in report:
            continue
        *periodic, kept = report[stage]
        steps = [entry["frames"] for entry in periodic]
        if f"{stage}_final" in report:  # trained on frames alone: judged with ground truth here
            kept = {"policy_frames": kept["policy_frames"], **report[f"{stage}_final"]}
            returns = distances.twinx()
            curve = [entry["mean_return"] for entry in periodic]
            returns.plot(steps, curve, "o:", color=COLORS[name])
            returns.set_ylabel("return (frames only, dotted)")
            # the return's curve, listed with the distances
            distances.plot([], [], "o:", color=COLORS[name], label=f"{name}: return (selection)")
            legend_x = 1.1
        else:
            distances.plot(
                steps,
                [entry["mean_distance"] for entry in periodic],
                "o-",
                color=COLORS[name],
                label=f"{name} (selection seeds)",
            )
        kept_policies = [(kept, "*", "kept")]
        if stage == "ppo_scratch" and "ppo_scratch_early" in report:
            early = report["ppo_scratch_early"]
            budget = report["settings"]["ppo_early_frames"]
            kept_policies.append((early, "P", f"kept within {budget:,} env steps"))
        for entry, marker, what in kept_policies:
            distances.plot(
                entry["policy_frames"],
                entry["mean_distance"],
                marker,
                markersize=13,
                color=COLORS[name],
                markeredgecolor="black",
                label=f"{name}, {what}: {entry['mean_distance']:.0f} m",
            )
    distances.set_ylabel("mean distance before collision (m)")
    distances.set_title(
        "PPO curves on the selection seeds; levels and kept policies on the evaluation seeds"
    )
    distances.legend(loc="upper left", bbox_to_anchor=(legend_x, 1.0), fontsize=9)
    for name, curves in scales.items():
        for action, style in zip(ACTION_NAMES, ("-", ":"), strict=True):
            points = curves.get(action, [])
            if points:
                steps, values = zip(*points, strict=True)
                scale_axes.plot(steps, values, style, color=COLORS[name], label=f"{name}: {action}")
    scale_axes.set_yscale("log")
    scale_axes.set_ylabel("action scale (before tanh)")
    scale_axes.set_xlabel("env steps (4 frames each)")
    if scales:
        scale_axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)


def write_json(path: Path, report: dict[str, Any]) -> None:
    """Print the report as JSON and write it to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
