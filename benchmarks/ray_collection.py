"""Env steps per second of Ray collection (1 and 2 workers) vs one process, same total sessions.

Every configuration steps ``--sessions`` world-model sessions in total with a constant policy on
embedded servers (one per env) and collects ``--batches`` timed batches of ``--steps`` steps per
session after one warm-up batch; prints JSON. One env step is one chunk of 4 frames per camera.

    .venv/bin/python benchmarks/ray_collection.py --sessions 4 --width 192 --height 128
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from collections.abc import Iterable
from typing import Any

import ray
import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector

from oasis_torchrl.config import EmbeddedServerConfig, EnvConfig
from oasis_torchrl.distributed import RayCollection, RayCollectionConfig, env_factory
from oasis_torchrl.envs import make_env

logger = logging.getLogger(__name__)


def constant_policy() -> TensorDictModule:
    """Half throttle, straight: no policy cost, so the figures are the collection path's."""
    net = nn.Sequential(nn.Linear(2, 8), nn.Tanh(), nn.Unflatten(-1, (4, 2)))
    with torch.no_grad():
        net[0].weight.zero_()
        net[0].bias.copy_(torch.tensor([0.5, 0.0] * 4))
    return TensorDictModule(net, in_keys=["state"], out_keys=["action"])


def timed(batches: Iterable[Any], count: int) -> tuple[int, float]:
    """Env steps and seconds of ``count`` batches after a warm-up one."""
    iterator = iter(batches)
    next(iterator)
    started, steps = time.perf_counter(), 0
    for _ in range(count):
        steps += next(iterator).numel()
    return steps, time.perf_counter() - started


def single_process(args: argparse.Namespace, env: EnvConfig) -> tuple[int, float]:
    env = make_env(env, num_envs=args.sessions, all_frames=False)
    collector = Collector(
        env,
        constant_policy(),
        frames_per_batch=args.sessions * args.steps,
        total_frames=-1,
        auto_register_policy_transforms=False,
    )
    try:
        return timed(collector, args.batches)
    finally:
        collector.shutdown()


def on_ray(args: argparse.Namespace, env: EnvConfig, workers: int) -> tuple[int, float]:
    if args.sessions % workers:
        raise ValueError(f"--sessions {args.sessions} is not divisible by {workers} workers")
    config = RayCollectionConfig(num_collectors=workers, sessions_per_env=args.sessions // workers)
    frames = args.sessions * args.steps
    with RayCollection(
        config,
        env_factory(env, config, all_frames=False),
        constant_policy(),
        frames_per_batch=frames,
        total_frames=frames * (args.batches + 2),
        auto_register_policy_transforms=False,
    ) as collection:
        return timed(collection, args.batches)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=4, help="total sessions (4)")
    parser.add_argument("--steps", type=int, default=8, help="steps per session per batch (8)")
    parser.add_argument("--batches", type=int, default=4, help="timed batches (4)")
    parser.add_argument("--width", type=int, default=192)
    parser.add_argument("--height", type=int, default=128)
    args = parser.parse_args()
    env = EnvConfig(
        max_steps=10_000,
        image_size=None,
        server=EmbeddedServerConfig(width=args.width, height=args.height),
    )
    ray.init(
        address="local",
        num_cpus=2,
        include_dashboard=False,
        logging_level=logging.WARNING,
        object_store_memory=200 * 1024**2,
    )
    results = []
    runs = {"single_process": lambda: single_process(args, env)}
    for workers in (1, 2):
        runs[f"ray_{workers}_workers"] = lambda w=workers: on_ray(args, env, w)
    try:
        for name, run in runs.items():
            steps, seconds = run()
            results.append(
                {
                    "mode": name,
                    "sessions": args.sessions,
                    "env_steps": steps,
                    "seconds": round(seconds, 3),
                    "env_steps_per_s": round(steps / seconds, 2),
                    "frames_per_s": round(4 * steps / seconds, 1),
                }
            )
    finally:
        ray.shutdown()
    print(
        json.dumps(
            {
                "benchmark": "ray_collection",
                "resolution": [args.width, args.height],
                "steps_per_batch": args.steps,
                "results": results,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
