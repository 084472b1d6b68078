"""Env steps per second with and without the rerun logger (default settings), same run.

One ``OasisEnv("local")`` (768x512, 4 rows, the embedded server in this process) is stepped in
alternating blocks: through the bare env, then through the same env with a ``RolloutLogger``
transform appended (default ``LogOptions``: every row, JPEG 85, ground truth, top-down map,
background writer) writing an ``.rrd`` file. Alternating cancels drift in machine load; each
logged block ends with ``flush()`` so the writer's backlog is paid inside the timing. On a
shared machine the load drifts between blocks, so besides the totals the report gives the median
of the per-round slowdowns, which one load spike cannot move much.
Target: at most 10% slower with the logger.

With ``--side-by-side`` it measures instead what recording policies side by side costs: the
evaluation of two policies (the autopilot and a constant throttle) on the same seeds, unlogged
(one ``Evaluator`` per policy, as ``oasis-torchrl eval`` runs without ``rerun``) against the same
evaluation recorded side by side into one ``.rrd``
(:func:`~oasis_torchrl.evaluation.evaluate_side_by_side`, ``eval compare=[...]``), in
alternating rounds; env start-up is inside both timings, as a user pays it.

Usage: ``python benchmarks/logging_overhead.py [--envs 4 --steps 4 --rounds 8]`` or
``python benchmarks/logging_overhead.py --side-by-side [--envs 4 --steps 30 --rounds 2]``;
prints JSON.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.viz import LogOptions, RerunTransform, RolloutLogger

PROMPTS = ["urban street", "rural road", "highway at sunset", "city at night"]
TARGET_MAX_SLOWDOWN = 0.10
SIDE_BY_SIDE_POLICIES = ("autopilot", "constant:throttle=0.6,steering=0.0")


def run_block(
    env: EnvBase, td: TensorDictBase, steps: int, generator: torch.Generator
) -> tuple[TensorDictBase, float]:
    """Step ``env`` ``steps`` times (resetting finished rows); returns the last td and seconds."""
    started = time.perf_counter()
    for _ in range(steps):
        action = torch.rand(env.action_spec.shape, generator=generator)
        action[..., 0] = action[..., 0] * 0.6 + 0.2  # mostly forward: the car moves
        action[..., 1] = action[..., 1] * 0.4 - 0.2
        _, td = env.step_and_maybe_reset(td.set("action", action))
    return td, time.perf_counter() - started


def measure(args: argparse.Namespace, rrd: Path) -> dict[str, list[float]]:
    """Seconds of each bare and each logged block, over ``rounds`` alternating pairs."""
    env = OasisEnv(
        "local",
        args.envs,
        PROMPTS[: args.envs],
        server=ServerConfig(width=args.width, height=args.height),
    )
    rerun_logger = RolloutLogger(rrd, LogOptions())
    logged_env = env.append_transform(RerunTransform(rerun_logger))
    generator = torch.Generator().manual_seed(0)
    seconds: dict[str, list[float]] = {"bare": [], "logged": []}
    try:
        td = logged_env.reset()
        td, _ = run_block(env, td, args.warmup, generator)
        for _ in range(args.rounds):
            td, elapsed = run_block(env, td, args.steps, generator)
            seconds["bare"].append(elapsed)
            started = time.perf_counter()
            td, _ = run_block(logged_env, td, args.steps, generator)
            rerun_logger.flush()
            seconds["logged"].append(time.perf_counter() - started)
    finally:
        rerun_logger.close()
        env.close()
    return seconds


def measure_side_by_side(args: argparse.Namespace, folder: Path) -> dict[str, list[float]]:
    """Seconds of each unlogged and each side-by-side evaluation, over ``rounds`` pairs."""
    from oasis_torchrl.evaluation import Evaluator, evaluate_side_by_side

    settings = [f"episodes={args.envs}", f"max_steps={args.steps}", "seeds=[1000]"]
    settings.append(f"env.image_size=[{args.height},{args.width}]")
    drivers = {spec: load_driver(spec) for spec in SIDE_BY_SIDE_POLICIES}
    seconds: dict[str, list[float]] = {"unlogged": [], "side_by_side": []}
    for index in range(args.rounds):
        cfg = load_config("eval", settings)
        started = time.perf_counter()
        for driver in drivers.values():
            with Evaluator.for_driver(cfg.env, cfg, driver, progress=False) as evaluator:
                evaluator.evaluate(driver)
        seconds["unlogged"].append(time.perf_counter() - started)
        cfg = load_config("eval", [*settings, f"rerun={folder / f'pair{index}.rrd'}"])
        started = time.perf_counter()
        evaluate_side_by_side(cfg.env, cfg, drivers, progress=False)
        seconds["side_by_side"].append(time.perf_counter() - started)
    return seconds


def side_by_side_report(args: argparse.Namespace) -> dict:
    """The side-by-side overhead as a JSON-ready report."""
    with tempfile.TemporaryDirectory() as folder:
        seconds = measure_side_by_side(args, Path(folder))
        rrd_bytes = sum(path.stat().st_size for path in Path(folder).glob("*.rrd"))
    ratios = [g / b for b, g in zip(seconds["unlogged"], seconds["side_by_side"], strict=True)]
    return {
        "benchmark": "logging_overhead_side_by_side",
        "policies": list(SIDE_BY_SIDE_POLICIES),
        "episodes_per_policy": args.envs,
        "max_steps": args.steps,
        "policy_frame_size": [args.height, args.width],
        "rounds": args.rounds,
        "seconds_unlogged": [round(s, 2) for s in seconds["unlogged"]],
        "seconds_side_by_side": [round(s, 2) for s in seconds["side_by_side"]],
        "time_ratio": round(sum(seconds["side_by_side"]) / sum(seconds["unlogged"]), 3),
        "median_round_ratio": round(statistics.median(ratios), 3),
        "rrd_bytes_per_recording": round(rrd_bytes / args.rounds),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=4, choices=range(1, len(PROMPTS) + 1))
    parser.add_argument("--width", type=int, default=768)
    parser.add_argument("--height", type=int, default=512)
    parser.add_argument("--steps", type=int, default=4, help="steps per block")
    parser.add_argument("--rounds", type=int, default=8, help="bare/logged block pairs")
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument(
        "--side-by-side",
        action="store_true",
        help="time an evaluation of two policies recorded side by side against it unlogged "
        "(--envs episodes per policy, --steps its max steps, --width/--height the policy's "
        "frames: use e.g. --width 96 --height 64)",
    )
    args = parser.parse_args()
    if args.side_by_side:
        print(json.dumps(side_by_side_report(args), indent=2))
        return
    with tempfile.TemporaryDirectory() as folder:
        rrd = Path(folder) / "overhead.rrd"
        seconds = measure(args, rrd)
        rrd_bytes = rrd.stat().st_size
    steps = args.steps * args.rounds
    bare, logged = steps / sum(seconds["bare"]), steps / sum(seconds["logged"])
    pair_slowdowns = [1 - b / g for b, g in zip(seconds["bare"], seconds["logged"], strict=True)]
    median_slowdown = statistics.median(pair_slowdowns)
    options = LogOptions()
    report = {
        "benchmark": "logging_overhead",
        "num_envs": args.envs,
        "frame_size": [args.height, args.width],
        "steps_per_side": steps,
        "logger": {
            "jpeg_quality": options.jpeg_quality,
            "background": options.background,
            "topdown": options.topdown,
            "rows": "all",
        },
        "env_steps_per_s_without_logger": round(bare, 3),
        "env_steps_per_s_with_logger": round(logged, 3),
        "slowdown": round(1 - logged / bare, 4),
        "median_pair_slowdown": round(median_slowdown, 4),
        "target_max_slowdown": TARGET_MAX_SLOWDOWN,
        "meets_target": median_slowdown <= TARGET_MAX_SLOWDOWN,
        "rrd_bytes_per_logged_step": round(rrd_bytes / (steps + 1)),
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
