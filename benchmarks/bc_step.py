"""A behaviour-cloning step: samples gathered one at a time vs a whole batch at once.

``oasis-torchrl train bc`` decodes the dataset once into memory
(:class:`~oasis_torchrl.train.bc_data.InMemoryBCDataset`). The baseline is how a ``DataLoader``
reads any map-style dataset: one ``__getitem__`` per sample (an indexing per key and sample,
a float conversion per sample), then ``default_collate`` stacks them; frames are kept at the
dataset's size and the policy's preprocessor resizes every batch. Ours: ``__getitems__`` gathers
the batch with one indexing per key, and the cache holds the frames at the policy's size.

The dataset: autopilot drives recorded by the embedded server at 96x64 with the privileged state
(the demonstrations ``oasis-torchrl demo`` records). A step is the trainer's own: fetch, the
policy's preprocessor, random shifts, the main job's loss (mixture head, manoeuvre loss,
auxiliary head), backward, AdamW. Timed at the default policy size (64x96, no resize) and at
32x48 (ours resized once, into the cache; the baseline every batch), best of ``--repeats`` runs
of ``--steps`` steps, same run.

Usage: ``python benchmarks/bc_step.py [--episodes 8 --steps 40 --repeats 3]``; prints JSON with
milliseconds per step and ``speedup`` (the baseline's time over ours; > 1: ours is faster).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

import torch
from torch.utils.data import DataLoader, Dataset

from oasis_torchrl.config import load_config
from oasis_torchrl.data import LeRobotRecorder
from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.train.bc import BCTrainer, open_dataset
from oasis_torchrl.train.bc_data import InMemoryBCDataset


class OneSampleAtATime(Dataset):
    """The cache behind the ``Dataset`` protocol's ``__getitem__`` alone (the baseline)."""

    def __init__(self, cached: InMemoryBCDataset) -> None:
        self.cached = cached

    def __len__(self) -> int:
        return len(self.cached)

    def __getitem__(self, position: int) -> dict[str, Any]:
        return self.cached[position]


def record(root: Path, episodes: int, steps: int) -> Path:
    """``episodes`` autopilot drives of ``steps`` chunks, frame rows with the privileged state."""
    env = OasisEnv(
        "local",
        num_envs=episodes,
        prompts="urban",
        server=ServerConfig(width=96, height=64),
        all_frames=True,
        max_steps=steps,
        expert=True,
    )
    try:
        with LeRobotRecorder(root, privileged=True) as recorder:
            recorder.write(env.rollout(steps, Autopilot(), break_when_any_done=False))
    finally:
        env.close()
    return root


def trainer(dataset: Path, output: Path, image_size: list[int], steps: int) -> BCTrainer:
    """The main job's BC trainer on ``dataset`` (its cache at the policy's size)."""
    cfg = load_config(
        "bc",
        [
            f"dataset.root={dataset}",
            f"output_dir={output}",
            f"policy.image_size=[{image_size[0]},{image_size[1]}]",
            "policy.loss=manoeuvre",
            "policy.aux_weight=1.0",
            f"train.steps={steps}",
            "train.save_every=0",
            "eval.episodes=0",
            "progress=false",
        ],
    )
    return BCTrainer(cfg)


def baseline_loader(ours: BCTrainer) -> DataLoader:
    """Per-sample fetches of a cache at the dataset's size (the preprocessor resizes), with
    ours' random shifts."""
    lerobot = open_dataset(ours.cfg.dataset, ours.policy_config)
    full_size = InMemoryBCDataset(
        lerobot, progress=False, frame_transform=ours.loader.dataset.frame_transform
    )
    return DataLoader(
        OneSampleAtATime(full_size),
        batch_size=ours.loader.batch_size,
        shuffle=True,
        drop_last=ours.loader.drop_last,
    )


def ms_per_step(run: BCTrainer, repeats: int) -> float:
    """Best wall time of ``repeats`` runs of the trainer's loop, per step."""
    steps = run.cfg.train.steps
    run.train()  # warm-up: allocator, thread pool, first batches
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run.train()
        best = min(best, time.perf_counter() - start)
    return 1000 * best / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=8, help="autopilot drives recorded")
    parser.add_argument("--chunks", type=int, default=40, help="chunks per drive")
    parser.add_argument("--steps", type=int, default=40, help="BC steps per timed run")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.manual_seed(0)
    results = []
    with tempfile.TemporaryDirectory() as scratch:
        dataset = record(Path(scratch) / "drives", args.episodes, args.chunks)
        for size in ([64, 96], [32, 48]):
            ours = trainer(dataset, Path(scratch) / "bc", size, args.steps)
            ours_ms = ms_per_step(ours, args.repeats)
            ours.loader = baseline_loader(ours)
            baseline_ms = ms_per_step(ours, args.repeats)
            results.append(
                {
                    "policy_image_size": size,
                    "rows": len(ours.loader.dataset),
                    "batch_size": ours.loader.batch_size,
                    "baseline_ms_per_step": round(baseline_ms, 2),
                    "ours_ms_per_step": round(ours_ms, 2),
                    "speedup": round(baseline_ms / ours_ms, 2),
                }
            )
    print(json.dumps({"frames": [64, 96], "threads": torch.get_num_threads(), "results": results}))


if __name__ == "__main__":
    main()
