"""How policies crash: what lay ahead, and what each policy did on its way into each collision.

A mean distance says how often a policy collides, not why. This script drives each policy
through the learning benchmark's evaluation episodes (urban, seed 1000, 32 episodes of up to 150
chunks) and reads the embedded server's ground truth over the last :data:`APPROACH_CHUNKS`
chunks before every collision: was a lane beside the car free when the approach began, did the
policy steer (a lane change) or brake on the way in, and where in its lane was the car. Over
every chunk of every episode it also gives the share spent riding the line between two lanes,
the one place from which an obstacle in either lane is a near miss or a collision.

Usage: ``python benchmarks/crashes.py POLICY [POLICY ...] [--episodes 32 --seed 1000]``
(policy folders, PPO checkpoints or driver specs such as ``autopilot``); prints JSON (about a
minute per policy on 2 cores).
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import torch
from tensordict import TensorDictBase

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.train.evaluate import EvalReport, Evaluator, episode_results, rollout_episodes

APPROACH_CHUNKS = 15
"""The approach: the last 3 s (15 chunks, about 40 m at cruise speed) before a collision, the
distance at which the autopilot starts its lane changes."""
FREE_MARGIN = 10.0
"""Metres: a lane beside is free when its nearest obstacle is this much farther than the one in
the car's lane (or it has none)."""
STEERS = 0.2
"""A chunk's mean ``|steering|`` above this is a lane change (the autopilot's are 0.2-0.5)."""
STRADDLES = 1.0
"""Metres from its lane's centre beyond which the car rides the line between two lanes (the
embedded roads' lanes are 3.2-3.6 m wide)."""


def drive(spec: str, args: argparse.Namespace) -> tuple[TensorDictBase, EvalReport]:
    """The evaluation's rollout ``[episodes, chunks]`` of the driver ``spec``, and its report."""
    cfg = load_config(
        "eval",
        [
            f"policy={spec}",
            f"episodes={args.episodes}",
            f"seeds=[{args.seed}]",
            f"max_steps={args.max_steps}",
            f"prompts=[{args.prompt}]",
        ],
    )
    driver = load_driver(spec)
    with Evaluator.for_driver(cfg.env, cfg, driver, progress=False) as evaluator:
        evaluator.env.set_seed(args.seed)
        rollout = rollout_episodes(evaluator.env, driver, args.max_steps)
    return rollout, EvalReport(episode_results(rollout))


def approach(truth: dict[str, torch.Tensor], actions: torch.Tensor, end: int) -> dict[str, Any]:
    """What one collided episode's approach held: ``truth`` fields and ``actions`` ``[T, 2]``
    per chunk (the chunk's last frame, its mean action), the collision at chunk ``end``."""
    start = max(end - APPROACH_CHUNKS, 0)
    ahead = float(truth["lane_obstacle_distance"][start])
    beside = [
        truth[f"lanes_{side}"][start] > 0
        and truth[f"lane_obstacle_distance_{side}"][start] > ahead + FREE_MARGIN
        for side in ("left", "right")
    ]
    throttle, steering = actions[start:end].unbind(-1)
    return {
        "free_lane_beside": bool(any(beside)),
        "steered": bool((steering.abs() > STEERS).any()),
        "braked": bool((throttle < 0).any()),
        "straddling": bool(truth["lane_offset"][start].abs() > STRADDLES),
        "throttle": float(throttle.mean()) if end > start else None,
    }


def crash_report(rollout: TensorDictBase, report: EvalReport) -> dict[str, Any]:
    """The policy's distance and collisions, what its approaches held (counts over the
    collisions) and its share of chunks riding a lane line."""
    truth = {key: value[..., -1] for key, value in rollout.get(("next", "truth")).items()}
    actions = rollout.get("action").mean(-2)  # [episodes, chunks, 2]: each chunk's mean
    approaches = [
        approach({key: value[row] for key, value in truth.items()}, actions[row], episode.steps - 1)
        for row, episode in enumerate(report.episodes)
        if episode.collided
    ]
    driven = torch.arange(truth["speed"].shape[1]) < torch.tensor(
        [episode.steps for episode in report.episodes]
    ).unsqueeze(1)
    counts = {
        key: sum(entry[key] for entry in approaches)
        for key in ("free_lane_beside", "steered", "braked", "straddling")
    }
    throttles = [entry["throttle"] for entry in approaches if entry["throttle"] is not None]
    return {
        **report.summary(),
        "collisions": len(approaches),
        "approaches": counts,
        "approach_throttle": round(sum(throttles) / len(throttles), 3) if throttles else None,
        "straddling_share": round(
            float((truth["lane_offset"].abs() > STRADDLES)[driven].float().mean()), 3
        ),
        "mean_speed": round(float(truth["speed"][driven].mean()), 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+", help="policy folders, checkpoints or driver specs")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--prompt", default="urban")
    parser.add_argument("--max-steps", type=int, default=150, help="chunks per episode")
    args = parser.parse_args()
    report: dict[str, Any] = {"settings": vars(args)}
    for spec in args.policies:
        report[spec] = crash_report(*drive(spec, args))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
