"""Learning benchmark: do the policies really learn to drive in the world model?

On the embedded server, "urban" prompt, the demo's resolution (96x64 frames, 64x96 policy
images), fixed evaluation seeds, one episode per env row of up to ``--max-steps`` chunks:

1. references: the autopilot (privileged expert) and constant actions (straight ahead, a sweep
   of throttles; the best one is "the best constant action");
2. behaviour cloning on autopilot demonstrations (recorded with noise injected into the
   executed actions, then DAgger rounds); target: at least 70% of the autopilot's mean distance
   before collision;
3. PPO from scratch for ``--ppo-frames`` env steps; target: at least 1.5x the best constant
   action's mean distance;
4. PPO fine-tuning of the cloned policy; target: beats behaviour cloning alone.

Each PPO stage keeps the policy its periodic evaluations on ``--selection-seeds`` rate best
(early stopping), then evaluates that one on the evaluation seeds, which no choice has seen.

Prints JSON (every evaluation, the targets and whether they are met, the exact settings and
wall times) and writes it with a PNG of the learning curves to ``--results``. Stages cache
their outputs under ``--work`` (a rerun reuses finished stages). Budgets are stated in env
steps: one env step is one chunk of 4 world-model frames (so frames = 4 x steps).

Usage: ``python benchmarks/learning.py [--work outputs/learning] [--ppo-frames 61440]``
(about two and a half hours on 2 CPU cores). ``--stages`` runs some stages only, e.g. PPO
from scratch in one process (``--stages ppo_scratch``) and the rest in another; a last run
with every stage then assembles the report from the cache. A partial run writes what it ran,
with the targets its stages allow, to ``learning_<stages>.json`` and ``.png`` beside the full
report.
"""

from __future__ import annotations

import argparse
import json
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from PIL import Image, ImageDraw

from oasis_torchrl.config import load_config
from oasis_torchrl.train.pipeline import (
    clone,
    demonstrations,
    evaluate_all,
    ppo_config,
    run_ppo,
    timed_stage,
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
STAGES = ("references", "bc", "bc_ppo", "ppo_scratch")
COLORS = {
    "autopilot": (40, 40, 40),
    "best constant": (150, 150, 150),
    "bc": (31, 119, 180),
    "ppo (scratch)": (214, 39, 40),
    "bc + ppo": (44, 160, 44),
    "ppo (scratch), kept": (214, 39, 40),
    "bc + ppo, kept": (44, 160, 44),
}


class StageCache:
    """Evaluations and stage wall times kept in a JSON file under the work folder, so a rerun
    (or a run split over processes with ``--stages``) reuses them: an evaluation is keyed by
    policy name, spec and evaluation settings; a stage's time is the first run's."""

    def __init__(self, path: Path) -> None:
        self.path = path
        saved = json.loads(path.read_text()) if path.exists() else {}
        self.evaluations: dict[str, dict[str, float]] = saved.get("evaluations", {})
        self.seconds: dict[str, float] = saved.get("seconds", {})

    def evaluate(self, cfg: DictConfig, policies: dict[str, str]) -> dict[str, dict[str, float]]:
        """``evaluate_all`` of the policies not evaluated yet with these settings."""
        settings = (
            f"episodes={cfg.eval.episodes} seeds={list(cfg.eval.seeds)} steps={cfg.eval.max_steps}"
        )
        keys = {name: f"{name} {spec} {settings}" for name, spec in policies.items()}
        missing = {
            name: spec for name, spec in policies.items() if keys[name] not in self.evaluations
        }
        if missing:
            for name, summary in evaluate_all(cfg, missing).items():
                self.evaluations[keys[name]] = summary
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


def benchmark_config(args: argparse.Namespace) -> DictConfig:
    """The pipeline config of the benchmark: the demo's (:class:`~oasis_torchrl.config.DemoConfig`:
    its resolution, reward and settings) with the benchmark's budgets, episode length and
    evaluation seeds."""
    seeds = ",".join(str(seed) for seed in args.eval_seeds)
    return load_config(
        "demo",
        [
            f"output_dir={args.work}",
            f"env.max_steps={args.max_steps}",
            f"record.episodes={args.demo_episodes}",
            f"bc.train.steps={args.bc_steps}",
            f"dagger.rounds={args.dagger_rounds}",
            f"dagger.episodes={args.dagger_episodes}",
            f"dagger.steps={args.dagger_steps}",
            f"eval.max_steps={args.max_steps}",
            f"eval.episodes={args.eval_episodes}",
            f"eval.seeds=[{seeds}]",
            "eval.reference=[]",
            "progress=false",
        ],
    )


def ppo_stage(
    cfg: DictConfig,
    init_from: Path | None,
    name: str,
    frames: int,
    args: argparse.Namespace,
) -> DictConfig:
    """A PPO stage of the benchmark: its own folder, budget and evaluations on the selection
    seeds every ``EVAL_EVERY`` batches; fine-tuning (``init_from`` set) takes the demo's ``ppo``
    overrides, PPO from scratch the :class:`~oasis_torchrl.config.PPOConfig` defaults;
    ``args.ppo_overrides`` (``KEY=VALUE``) last."""
    stage = ppo_config(cfg, init_from, name, fine_tune=init_from is not None)
    evaluations = {
        "every": EVAL_EVERY,
        "episodes": cfg.eval.episodes,
        "selection_seeds": list(args.selection_seeds),
    }
    budget = {"collector": {"total_frames": frames}, "eval": evaluations}
    return OmegaConf.merge(stage, budget, OmegaConf.from_dotlist(args.ppo_overrides))


def plot(
    curves: dict[str, list[tuple[float, float]]], levels: dict[str, float], path: Path
) -> None:
    """Eval distance vs env steps (lines) and reference levels (horizontal), as a PNG."""
    width, height, margin = 900, 520, 70
    image = Image.new("RGB", (width, height), "white")
    draw = ImageDraw.Draw(image)
    points = [point for curve in curves.values() for point in curve]
    x_max = max((x for x, _ in points), default=1.0) or 1.0
    y_max = 1.1 * max([y for _, y in points] + list(levels.values()) + [1.0])

    def to_pixel(x: float, y: float) -> tuple[float, float]:
        return (
            margin + (width - 2 * margin) * x / x_max,
            height - margin - (height - 2 * margin) * y / y_max,
        )

    draw.rectangle([margin, margin, width - margin, height - margin], outline="black")
    for k in range(6):
        y = y_max * k / 5
        draw.text((8, to_pixel(0, y)[1] - 6), f"{y:.0f} m", fill="black")
        x = x_max * k / 5
        draw.text((to_pixel(x, 0)[0] - 15, height - margin + 8), f"{x:.0f}", fill="black")
    draw.text((width / 2 - 90, height - 30), "env steps (4 frames each)", fill="black")
    title = "mean distance before collision (PPO curves: selection seeds; levels: eval seeds)"
    draw.text((margin, 20), title, fill="black")
    legend_y = margin + 8
    for name, level in levels.items():
        color = COLORS.get(name, (0, 0, 0))
        y = to_pixel(0, level)[1]
        for x in range(margin, width - margin, 12):
            draw.line([x, y, x + 6, y], fill=color, width=2)
        draw.text((width - margin - 170, legend_y), f"- - {name} {level:.0f} m", fill=color)
        legend_y += 16
    for name, curve in curves.items():
        color = COLORS.get(name, (0, 0, 0))
        pixels = [to_pixel(x, y) for x, y in curve]
        if len(pixels) > 1:
            draw.line(pixels, fill=color, width=3)
        for px, py in pixels:
            draw.ellipse([px - 3, py - 3, px + 3, py + 3], fill=color)
        draw.text((width - margin - 170, legend_y), f"--- {name}", fill=color)
        legend_y += 16
    path.parent.mkdir(parents=True, exist_ok=True)
    image.save(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=Path("outputs/learning"))
    parser.add_argument("--results", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("--max-steps", type=int, default=150, help="chunks per episode")
    parser.add_argument("--eval-episodes", type=int, default=32)
    parser.add_argument("--eval-seeds", type=int, nargs="+", default=[1000])
    parser.add_argument(
        "--selection-seeds",
        type=int,
        nargs="+",
        default=[2000],
        help="seeds of PPO's periodic evaluations, which pick the policy each PPO stage keeps",
    )
    parser.add_argument("--demo-episodes", type=int, default=64)
    parser.add_argument("--bc-steps", type=int, default=3000)
    parser.add_argument("--dagger-rounds", type=int, default=6)
    parser.add_argument("--dagger-episodes", type=int, default=32)
    parser.add_argument("--dagger-steps", type=int, default=1000)
    parser.add_argument("--ppo-frames", type=int, default=61440, help="PPO from scratch, env steps")
    parser.add_argument(
        "--stages",
        nargs="+",
        choices=STAGES,
        default=list(STAGES),
        help="run only these stages (each caches under --work; the report needs all of them)",
    )
    parser.add_argument("--finetune-frames", type=int, default=20480, help="BC + PPO, env steps")
    parser.add_argument(
        "--ppo-overrides",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="PPO settings of both PPO stages, e.g. ray.enabled=true (collection on two Ray "
        "workers, each with its own embedded server: 1.3x the env steps per second here)",
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")

    cfg = benchmark_config(args)
    cache = StageCache(args.work / "stages.json")
    results = run_stages(args, cfg, cache)
    settings = {
        "settings": {**vars(args), "work": str(args.work), "results": str(args.results)},
        "config": OmegaConf.to_container(cfg),
    }
    # A partial run (e.g. one stage on its own) leaves what it ran beside the full report.
    name = "learning" if set(results) == set(STAGES) else f"learning_{'_'.join(results)}"
    report = {**settings, **summarise(results), "seconds": cache.seconds}
    write_json(args.results / f"{name}.json", report)
    plot_report(report, args.results / f"{name}.png")
    if name != "learning":
        logger.info("ran %s; the full report needs every stage", list(results))


def run_stages(args: argparse.Namespace, cfg: DictConfig, cache: StageCache) -> dict[str, Any]:
    """Run (or reuse) the stages of ``args.stages``; their results, by stage, in stage order."""
    stages = set(args.stages)
    results: dict[str, Any] = {}
    if "references" in stages:
        with cache.timed("references"):
            results["references"] = cache.evaluate(cfg, REFERENCES)
    if stages & {"bc", "bc_ppo"}:
        with cache.timed("record"):
            dataset = demonstrations(cfg, Path(cfg.output_dir) / "demos")
        with cache.timed("bc"):
            bc_policy = clone(cfg, dataset)
        if "bc" in stages:
            results["bc"] = cache.evaluate(cfg, {"bc": str(bc_policy)})["bc"]
    if "bc_ppo" in stages:
        with cache.timed("bc_ppo"):
            finetune = ppo_stage(cfg, bc_policy, "bc_ppo", args.finetune_frames, args)
            results["bc_ppo"] = run_ppo(finetune).history
    if "ppo_scratch" in stages:
        with cache.timed("ppo_scratch"):
            scratch = ppo_stage(cfg, None, "ppo_scratch", args.ppo_frames, args)
            results["ppo_scratch"] = run_ppo(scratch).history
    return results


def summarise(results: dict[str, Any]) -> dict[str, Any]:
    """The stages' results with the best constant action and every target their stages allow
    (each met or not): BC needs the references, PPO from scratch the references, BC + PPO the
    clone."""
    report = dict(results)
    targets: dict[str, float | bool] = {}
    bc = results["bc"]["mean_distance"] if "bc" in results else None
    if "references" in results:
        references = results["references"]
        report["best_constant"] = best_constant(references)
        autopilot = references["autopilot"]["mean_distance"]
        constant = references[report["best_constant"]]["mean_distance"]
        if bc is not None:
            targets["bc_over_autopilot"] = bc / autopilot
            targets["bc_target_met"] = bc >= 0.7 * autopilot
        if "ppo_scratch" in results:
            scratch = results["ppo_scratch"][-1]["mean_distance"]
            targets["ppo_scratch_over_best_constant"] = scratch / constant
            targets["ppo_scratch_target_met"] = scratch >= 1.5 * constant
    if bc is not None and "bc_ppo" in results:
        finetune = results["bc_ppo"][-1]["mean_distance"]
        targets["bc_ppo_over_bc"] = finetune / bc
        targets["bc_ppo_target_met"] = finetune > bc
    report["targets"] = targets
    return report


def best_constant(references: dict[str, dict[str, float]]) -> str:
    """The name of the constant action that drives furthest."""
    constants = [name for name in REFERENCES if name.startswith("constant")]
    return max(constants, key=lambda name: references[name]["mean_distance"])


def plot_report(report: dict[str, Any], path: Path) -> None:
    """The PPO stages' curves (their last point, the kept policy, as a level) against the
    reference and BC levels of whichever stages the report holds, as a PNG."""
    curves: dict[str, list[tuple[float, float]]] = {}
    levels: dict[str, float] = {}
    if "references" in report:
        references = report["references"]
        levels["autopilot"] = references["autopilot"]["mean_distance"]
        levels["best constant"] = references[report["best_constant"]]["mean_distance"]
    if "bc" in report:
        levels["bc"] = report["bc"]["mean_distance"]
    for stage, name in (("ppo_scratch", "ppo (scratch)"), ("bc_ppo", "bc + ppo")):
        if stage in report:
            *periodic, kept = report[stage]
            curves[name] = [(entry["frames"], entry["mean_distance"]) for entry in periodic]
            levels[f"{name}, kept"] = kept["mean_distance"]
    plot(curves, levels, path)


def write_json(path: Path, report: dict[str, Any]) -> None:
    """Print the report as JSON and write it to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
