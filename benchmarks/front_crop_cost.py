"""The cost of the narrow forward crop (``env.front_crop``) per env step: with it / without it.

Two envs of the same settings (``make_env``, the main job's 64x96 policy images and frame
stack), one with ``env.front_crop`` and one without, step alternately with the same actions,
one timed block at a time; the ratio of their median seconds per env step is the crop's cost.
With the crop the embedded server renders large enough for it (96x64 / fraction) and the
client decodes every camera from that size, cutting the crop from the full-size front frame.
``--hosted`` runs both on the hosted-like server (VP9, at ``--hosted-size``; then the crop
costs the client its full-size RGB conversion of the front frame, the server the same work).

Usage: ``python benchmarks/front_crop_cost.py [--crop 0.25 --envs 4 --steps 10 --repeats 3]``;
prints JSON.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from typing import Any

import torch

from oasis_torchrl.config import EmbeddedServerConfig, EnvConfig
from oasis_torchrl.envs import make_env


def seconds_per_step(env: Any, steps: int) -> float:
    """Seconds per env step over ``steps`` steps of half throttle, straight."""
    action = torch.zeros(env.action_spec.shape)
    action[..., 0] = 0.5
    td = env.reset()
    started = time.perf_counter()
    for _ in range(steps):
        _, td = env.step_and_maybe_reset(td.set("action", action))
    return (time.perf_counter() - started) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--crop", type=float, default=0.25, help="env.front_crop")
    parser.add_argument("--envs", type=int, default=4)
    parser.add_argument("--steps", type=int, default=10, help="env steps per timed block")
    parser.add_argument("--repeats", type=int, default=3, help="timed blocks per env")
    parser.add_argument("--hosted", action="store_true", help="the hosted-like VP9 server")
    parser.add_argument("--hosted-size", type=int, nargs=2, default=[512, 768], metavar=("H", "W"))
    args = parser.parse_args()
    height, width = args.hosted_size if args.hosted else (64, 96)
    server = EmbeddedServerConfig(width=width, height=height, hosted=args.hosted)
    base = EnvConfig(num_envs=args.envs, max_steps=10_000, server=server)
    envs = {
        "without": make_env(base, all_frames=False),
        "with": make_env(base, all_frames=False, front_crop=args.crop),
    }
    timings: dict[str, list[float]] = {name: [] for name in envs}
    try:
        for env in envs.values():
            seconds_per_step(env, 2)  # start the server, warm the decoders
        for _ in range(args.repeats):
            for name, env in envs.items():
                timings[name].append(seconds_per_step(env, args.steps))
        render = {
            name: [env.base_env.server.config.height, env.base_env.server.config.width]
            for name, env in envs.items()
        }
    finally:
        for env in envs.values():
            env.close()
    median = {name: statistics.median(values) for name, values in timings.items()}
    report = {
        "settings": vars(args),
        "server_render_size": render,
        "seconds_per_env_step": timings,
        "median_seconds_per_env_step": median,
        "ratio_with_over_without": median["with"] / median["without"],
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
