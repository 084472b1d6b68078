"""The depth-collision reward on the small depth network vs on ground-truth depth, same frames.

The frames-only reward (the reference SDK's depth-collision reward) needs a depth model; offline
that is the small network ``oasis-torchrl train depth`` ships. This script drives held-out
episodes on the embedded server (scenes from ``DEPTH_HELD_OUT_PROMPTS`` and a seed, neither used
by training) with the front frames as the hosted model sends them (rendered at twice the policy's
size, VP9, decoded down to it) and, at every step, computes the reward's collision risk twice:
from the small network on the frame, and from the simulator's metric depth of the same frame
(:class:`~oasis_torchrl.rewards.GroundTruthDepth`, averaged down to the same pixels). Reported:

- ``terminations``: steps where both, only the network, only the truth, or neither end the
  episode (risk >= 1), and the share where they agree;
- ``risk_pearson``: correlation of the two risks over all steps;
- ``ground_truth_vs_render_size``: the same two figures between ground truth at the frames'
  size and at the rendered size: how much the reward itself gains from more pixels;
- ``collisions``: true collisions (the simulator's collision flag) and the share each source
  flags before it happens (risk 1 within ``--lead`` steps before the colliding step);
- ``cpu``: process CPU seconds per frame of the reward with each source and with no depth at all
  (the forward and straightness terms alone), and the ratios.

Usage: ``python benchmarks/depth_agreement.py [--envs 4 --steps 60 --weights PATH]``; prints
JSON.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np
import torch
from tensordict import TensorDictBase

from oasis_torchrl.config.reward_networks import DEPTH_HELD_OUT_PROMPTS, DepthTrainConfig
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.models.depth import nearness_target
from oasis_torchrl.rewards import (
    CallableDepth,
    DepthCollisionConfig,
    DepthCollisionReward,
    DepthSource,
    GroundTruthDepth,
    collision_risk,
)
from oasis_torchrl.rewards.depth_net import load_small_depth
from oasis_torchrl.train.depth import CAMERA, depth_env

DRIVERS = (
    "constant:throttle=1.0,steering=0.0",
    "scripted:throttle=0.8,steering=weave:0.088:20:100",
    "autopilot",
)


def drive(args: argparse.Namespace) -> list[TensorDictBase]:
    """One rollout ``[envs, steps]`` per driver, episodes ending at collisions."""
    settings = DepthTrainConfig(
        image_size=[args.height, args.width],
        render_scale=args.render_scale,
        prompts=list(args.prompts),
        drivers=list(args.drivers),
        num_envs=args.envs,
        episodes=args.envs,
        steps=args.steps,
        seed=args.seed,
    )
    drivers = [load_driver(spec) for spec in settings.drivers]
    env = depth_env(settings, drivers)
    rollouts = []
    try:
        env.set_seed(settings.seed)
        for driver in drivers:
            rollouts.append(env.rollout(args.steps, driver, break_when_any_done=False)["next"])
    finally:
        env.close()
    return rollouts


def risks(step: TensorDictBase, source: Callable[[torch.Tensor], torch.Tensor]) -> np.ndarray:
    """Collision risk ``[N, T]`` of every step from ``source(frames, depth)`` nearness."""
    frames = step["pixels", CAMERA].flatten(0, 1)
    depth = step["depth", CAMERA].flatten(0, 1)
    risk, _ = collision_risk(source(frames, depth), DepthCollisionConfig())
    return risk.view(step.batch_size).numpy()


def flagged_before(risk: np.ndarray, collided: np.ndarray, start: np.ndarray, lead: int) -> float:
    """Share of collision steps preceded (within ``lead`` steps of the same episode) by risk 1."""
    hits = []
    for row, step in zip(*np.nonzero(collided), strict=True):
        first = max(start[row, step], step - lead)
        hits.append(bool((risk[row, first:step] >= 1).any()))
    return float(np.mean(hits)) if hits else float("nan")


def episode_starts(done: np.ndarray) -> np.ndarray:
    """For every step ``[N, T]``, the step its episode started at."""
    starts = np.zeros(done.shape, dtype=np.int64)
    for row in range(done.shape[0]):
        first = 0
        for step in range(done.shape[1]):
            starts[row, step] = first
            if done[row, step]:
                first = step + 1
    return starts


def agreement(args: argparse.Namespace, rollouts: list[TensorDictBase]) -> dict:
    """Terminations, correlation and collisions flagged, from both sources."""
    small = load_small_depth(CAMERA, args.weights)
    scale = args.render_scale
    per_source: dict[str, list[np.ndarray]] = {"small_net": [], "ground_truth": [], "render": []}
    collided, starts = [], []
    for step in rollouts:
        per_source["small_net"].append(risks(step, lambda frames, depth: small.nearness(frames)))
        per_source["ground_truth"].append(
            risks(step, lambda frames, depth: nearness_target(depth, scale))
        )
        per_source["render"].append(risks(step, lambda frames, depth: nearness_target(depth)))
        collided.append(step["truth", "collided"].amax(-1).numpy() > 0.5)
        starts.append(episode_starts(step["done"].squeeze(-1).numpy()))
    net, truth, render = (np.concatenate(values, 1) for values in per_source.values())
    hit, start = np.concatenate(collided, 1), np.concatenate(starts, 1)
    # Rollouts are concatenated along time: offset each one's episode starts.
    offsets = np.repeat(np.arange(len(rollouts)) * args.steps, args.steps)
    start = start + offsets[None, :]
    net_ends, truth_ends = net >= 1, truth >= 1
    terminations = {
        "both": int((net_ends & truth_ends).sum()),
        "only_small_net": int((net_ends & ~truth_ends).sum()),
        "only_ground_truth": int((~net_ends & truth_ends).sum()),
        "neither": int((~net_ends & ~truth_ends).sum()),
    }
    return {
        "steps": int(net.size),
        "terminations": terminations,
        "termination_agreement": round(float((net_ends == truth_ends).mean()), 4),
        "risk_pearson": round(float(np.corrcoef(net.ravel(), truth.ravel())[0, 1]), 4),
        "risk_mean": {
            "small_net": round(float(net.mean()), 4),
            "ground_truth": round(float(truth.mean()), 4),
        },
        # How much the reward itself changes with resolution: ground truth at the frames' size
        # vs at the rendered size (render_scale times larger), the ceiling of a larger network.
        "ground_truth_vs_render_size": {
            "risk_pearson": round(float(np.corrcoef(truth.ravel(), render.ravel())[0, 1]), 4),
            "termination_agreement": round(float((truth_ends == (render >= 1)).mean()), 4),
        },
        "collisions": {
            "count": int(hit.sum()),
            "lead_steps": args.lead,
            "flagged_before_small_net": round(flagged_before(net, hit, start, args.lead), 4),
            "flagged_before_ground_truth": round(flagged_before(truth, hit, start, args.lead), 4),
        },
    }


def cpu_cost(args: argparse.Namespace, step: TensorDictBase) -> dict:
    """Process CPU seconds per frame of the reward with each depth source, and the ratios."""
    td = step[:, -1].clone()
    td["action"] = torch.full((td.batch_size[0], 4, 2), 0.5)
    depth = td["depth", CAMERA]
    td["depth", CAMERA] = (
        depth if args.render_scale == 1 else 1 / nearness_target(depth, args.render_scale)
    )
    sources: dict[str, DepthSource] = {
        "small_net": load_small_depth(CAMERA, args.weights),
        "ground_truth": GroundTruthDepth(CAMERA),
        "none": CallableDepth(lambda rgb: torch.zeros(rgb.shape[:3]), CAMERA),
    }
    seconds = {}
    for name, source in sources.items():
        reward = DepthCollisionReward(source)
        reward(td)  # warm-up
        started = time.process_time()
        for _ in range(args.repeats):
            reward(td)
        seconds[name] = (time.process_time() - started) / (args.repeats * td.batch_size[0])
    return {
        "batch": td.batch_size[0],
        "ms_per_frame": {name: round(value * 1e3, 4) for name, value in seconds.items()},
        "small_net_over_ground_truth": round(seconds["small_net"] / seconds["ground_truth"], 1),
        "small_net_over_none": round(seconds["small_net"] / seconds["none"], 1),
        "threads": torch.get_num_threads(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=4)
    parser.add_argument("--steps", type=int, default=60, help="steps per driver and row")
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--render-scale", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--prompts", nargs="+", default=list(DEPTH_HELD_OUT_PROMPTS))
    parser.add_argument("--drivers", nargs="+", default=list(DRIVERS))
    parser.add_argument("--lead", type=int, default=5, help="steps before a collision")
    parser.add_argument("--weights", default=None, help="weights file (default: the shipped)")
    parser.add_argument("--repeats", type=int, default=20, help="timed reward calls per source")
    args = parser.parse_args()
    started = time.perf_counter()
    rollouts = drive(args)
    report = {
        "frames": [args.height, args.width],
        "render_scale": args.render_scale,
        "envs": args.envs,
        "seed": args.seed,
        "drivers": args.drivers,
        **agreement(args, rollouts),
        "cpu": cpu_cost(args, rollouts[0]),
        "wall_seconds": round(time.perf_counter() - started, 1),
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
