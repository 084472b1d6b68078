"""Collision risk from ground-truth depth vs the other depth sources, on embedded-server rollouts.

The reference reward scores collision risk on a monocular depth estimate. On the embedded server
the metric depth is known, so every source can be compared with it on the same frames: rows
drive straight at a steady throttle through urban scenes (so they meet parked cars and
barriers), and at every step the front camera's risk is computed from

- ``ground_truth``: :class:`~oasis_torchrl.rewards.GroundTruthDepth` (the reference);
- ``noisy_ground_truth``: the ground-truth nearness times log-normal noise (sigma 0.15),
  standing in for a decent estimator;
- ``monocular``: :class:`~oasis_torchrl.rewards.MonocularDepth` with Depth-Anything-V2-Small when
  its weights are available offline; otherwise a small randomly initialised Depth-Anything built
  locally (an untrained network: a check that the path runs, not a quality figure).

Reported per source: mean |risk - ground-truth risk|, correlation with it, and how often its
termination decision (risk >= 1) agrees. Also: the ground-truth risk's correlation with the
simulator's distance to the nearest obstacle ahead (a sanity check of the risk itself).

Usage: ``python benchmarks/depth_risk.py [--envs 4 --steps 40]``; prints JSON.
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
import torch

from oasis_torchrl.drivers import ScriptedDriver
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.rewards import (
    DEFAULT_DEPTH_MODEL,
    DepthCollisionConfig,
    GroundTruthDepth,
    MonocularDepth,
    collision_risk,
)
from oasis_torchrl.sim.config import ServerConfig


def monocular_source() -> tuple[MonocularDepth, str]:
    """The real model if its weights load offline, else a tiny untrained one."""
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    try:
        from transformers import AutoModelForDepthEstimation

        model = AutoModelForDepthEstimation.from_pretrained(DEFAULT_DEPTH_MODEL)
        return MonocularDepth(model), DEFAULT_DEPTH_MODEL
    except OSError:
        from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config

        torch.manual_seed(0)
        backbone = Dinov2Config(
            hidden_size=32,
            num_hidden_layers=4,
            num_attention_heads=2,
            image_size=14,
            patch_size=14,
            out_indices=[1, 2, 3, 4],
            reshape_hidden_states=False,
        )
        config = DepthAnythingConfig(
            backbone_config=backbone,
            reassemble_hidden_size=32,
            neck_hidden_sizes=[16] * 4,
            fusion_hidden_size=16,
            head_hidden_size=16,
        )
        model = DepthAnythingForDepthEstimation(config).eval()
        return MonocularDepth(model, input_size=140), "untrained local Depth-Anything (offline)"


def compare(reference: np.ndarray, other: np.ndarray) -> dict:
    corr = np.corrcoef(reference, other)[0, 1] if reference.std() and other.std() else float("nan")
    return {
        "mean_abs_diff": round(float(np.abs(reference - other).mean()), 4),
        "correlation": round(float(corr), 3),
        "termination_agreement": round(float(((reference >= 1) == (other >= 1)).mean()), 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=4)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--width", type=int, default=192)
    parser.add_argument("--height", type=int, default=128)
    args = parser.parse_args()
    config = DepthCollisionConfig()
    generator = torch.Generator().manual_seed(0)
    monocular, monocular_name = monocular_source()
    truth_source = GroundTruthDepth("front")
    sources = {
        "ground_truth": truth_source,
        # nearness * log-normal noise: an imperfect estimator with the right structure
        "noisy_ground_truth": lambda td: (
            truth_source(td)
            * torch.exp(0.15 * torch.randn(td["depth", "front"].shape, generator=generator))
        ),
        "monocular": monocular,
    }
    env = OasisEnv(
        "local",
        args.envs,
        "urban street",
        server=ServerConfig(width=args.width, height=args.height),
        depth_cameras=("front",),
        max_steps=args.steps,
    )
    driver = ScriptedDriver.from_spec("throttle=0.6,steering=0")
    risks: dict[str, list[np.ndarray]] = {name: [] for name in sources}
    obstacle_distance = []
    try:
        env.set_seed(0)
        td = env.reset()
        for _ in range(args.steps):
            td = env.step(driver(td))["next"]
            for name, source in sources.items():
                risks[name].append(collision_risk(source(td), config)[0].flatten().numpy())
            obstacle_distance.append(td["truth", "obstacle_distance"][:, -1].numpy())
    finally:
        env.close()
    reference = np.concatenate(risks["ground_truth"])
    nearest = np.minimum(np.concatenate(obstacle_distance), 60.0)
    report = {
        "frames": int(reference.size),
        "size": [args.height, args.width],
        "monocular_model": monocular_name,
        "ground_truth_risk_mean": round(float(reference.mean()), 4),
        "ground_truth_risk_vs_obstacle_distance_correlation": round(
            float(np.corrcoef(reference, -nearest)[0, 1]), 3
        ),
        "sources": {
            name: compare(reference, np.concatenate(values))
            for name, values in risks.items()
            if name != "ground_truth"
        },
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
