"""Size and load time of a rerun recording: camera frames raw against JPEG, same episodes.

The autopilot drives a few evaluation episodes once (every frame of every chunk kept); the same
rollout is then logged twice by a ``RolloutLogger`` into an ``.rrd`` file: the baseline the way
rerun logs frames unless told otherwise (raw ``Image`` s, all 4 frames of each step:
``LogOptions(jpeg_quality=None, all_frames=True)``) and the default ``LogOptions()`` (the last
frame of each step, the one a policy acts on, as a JPEG ``EncodedImage``). Each file is read
back whole with rerun's own loader (``rerun.experimental.RrdReader`` on rerun-sdk 0.32 and newer,
``rerun.dataframe.load_recording`` before), the step before a viewer can show it. The report
gives bytes per logged episode-step, seconds to load and their ratios. A short recording's
bytes per step include what every file holds once (styles, layout, summary), so the default
way is also logged for the first half of the steps alone: the difference is the cost of a step,
which gives the size the main job's ``eval.rrd`` would reach (16 episodes x 2 policies x 150
steps, no crash; target 50 MB) if its scenes were this benchmark's.

Usage: ``python benchmarks/recording_size.py [--episodes 2 --steps 30 --size 64 96]``; prints
JSON.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import rerun as rr
import torch
from tensordict import TensorDictBase

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.envs.factory import make_env
from oasis_torchrl.evaluation import rollout_episodes
from oasis_torchrl.viz import LogOptions, RolloutLogger

MAIN_JOB_EPISODE_STEPS = 16 * 2 * 150
"""Episode-steps of the main job's eval.rrd at most: 16 episodes, 2 policies, 150 steps."""
TARGET_MAIN_JOB_BYTES = 50e6
WAYS = {
    "raw": LogOptions(jpeg_quality=None, all_frames=True),
    "default": LogOptions(),
}


def drive(episodes: int, steps: int, size: tuple[int, int], seed: int) -> TensorDictBase:
    """The autopilot's evaluation episodes ``[episodes, T]``, with every camera frame."""
    cfg = load_config("eval", [f"episodes={episodes}", f"max_steps={steps}"])
    driver = load_driver("autopilot")
    env = make_env(
        cfg.env,
        num_envs=episodes,
        prompts=[str(prompt) for prompt in cfg.prompts for _ in range(episodes)][:episodes],
        max_steps=steps,
        image_size=size,
        all_frames=True,
        frame_stack=driver.frame_stack,
        expert=driver.needs_expert,
    )
    try:
        env.set_seed(seed)
        return rollout_episodes(env, driver, steps, keep_pixels=True)
    finally:
        env.close()


def episode_steps(rollout: TensorDictBase) -> int:
    """Steps logged: each row's, up to and including the one that ends its episode."""
    done = rollout.get(("next", "done")).reshape(rollout.batch_size).int()
    ended_before = torch.cumsum(done, dim=1) - done
    return int((ended_before == 0).sum())


def load_seconds(path: Path) -> float:
    """Seconds for rerun's own loader to read the whole recording."""
    started = time.perf_counter()
    try:
        from rerun.experimental import RrdReader
    except ImportError:  # rerun-sdk < 0.32
        rr.dataframe.load_recording(str(path))
    else:
        RrdReader(path).stream().collect()
    return time.perf_counter() - started


def marginal_bytes(rollout: TensorDictBase, folder: Path, options: LogOptions) -> float:
    """Bytes a logged episode-step adds: the whole rollout against its first half."""
    half = rollout[:, : rollout.batch_size[1] // 2]
    small = measure(half, folder / "half.rrd", options)["bytes"]
    large = measure(rollout, folder / "whole.rrd", options)["bytes"]
    return (large - small) / (episode_steps(rollout) - episode_steps(half))


def measure(rollout: TensorDictBase, path: Path, options: LogOptions) -> dict[str, float]:
    """Bytes, seconds to write and seconds to load of ``rollout`` logged with ``options``."""
    started = time.perf_counter()
    with RolloutLogger(path, options) as rerun_logger:
        rerun_logger.log_rollout(rollout)
    written = time.perf_counter() - started
    return {"bytes": path.stat().st_size, "write_s": written, "load_s": load_seconds(path)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--steps", type=int, default=30, help="max steps per episode")
    parser.add_argument("--size", type=int, nargs=2, default=[64, 96], help="height width")
    parser.add_argument("--seed", type=int, default=1000)
    args = parser.parse_args()
    rollout = drive(args.episodes, args.steps, tuple(args.size), args.seed)
    steps = episode_steps(rollout)
    with tempfile.TemporaryDirectory() as folder:
        found = {way: measure(rollout, Path(folder) / f"{way}.rrd", o) for way, o in WAYS.items()}
        per_step = marginal_bytes(rollout, Path(folder), WAYS["default"])
        fixed = found["default"]["bytes"] - per_step * steps
    raw, default = found["raw"], found["default"]
    report = {
        "benchmark": "recording_size",
        "rerun_sdk": rr.__version__,
        "episodes": args.episodes,
        "episode_steps": steps,
        "frame_size": list(args.size),
        "raw_bytes_per_episode_step": round(raw["bytes"] / steps),
        "default_bytes_per_episode_step": round(default["bytes"] / steps),
        "size_ratio": round(default["bytes"] / raw["bytes"], 4),
        "raw_load_s": round(raw["load_s"], 3),
        "default_load_s": round(default["load_s"], 3),
        "load_time_ratio": round(default["load_s"] / raw["load_s"], 3),
        "raw_write_s": round(raw["write_s"], 2),
        "default_write_s": round(default["write_s"], 2),
        "default_bytes_per_added_episode_step": round(per_step),
        "main_job_mb_at_this_rate": round((fixed + per_step * MAIN_JOB_EPISODE_STEPS) / 1e6, 1),
        "target_main_job_mb": TARGET_MAIN_JOB_BYTES / 1e6,
        "meets_target": fixed + per_step * MAIN_JOB_EPISODE_STEPS <= TARGET_MAIN_JOB_BYTES,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
