"""Loading a dataset into behaviour cloning's memory cache: one LeRobot decode per episode vs one
pass per video file.

:class:`~oasis_torchrl.train.bc_data.InMemoryBCDataset` decodes every frame of every camera
before the first BC step, and the main job builds it again for each DAgger round, over a
dataset that grows each time. The baseline asks LeRobot's decoder for each episode's frames
(``decode_video_frames`` with the ``pyav`` backend: it opens the file, seeks to the keyframe
before the episode and decodes forward, once per episode and camera); ours decodes each video
file once in order (:func:`~oasis_torchrl.data.video_frames.frames_at`). Both build the whole
cache (the table, every camera, the frames at the policy's size) and must hold the same bytes.

The dataset: ``--dataset`` (e.g. a main job's ``demos/``, which holds its DAgger episodes too),
or ``--episodes`` demonstrations recorded as the main job's recording stage records them.
Alternating runs, the median of ``--repeats`` each.

Usage: ``python benchmarks/bc_cache.py [--dataset DIR | --episodes 16] [--repeats 3]``;
prints JSON with seconds per build and ``speedup`` (the baseline's over ours; > 1: ours is
faster).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import torch
from lerobot.datasets.video_utils import decode_video_frames

from oasis_torchrl.config import load_config
from oasis_torchrl.data.loading import open_for_bc
from oasis_torchrl.train.bc_data import InMemoryBCDataset
from oasis_torchrl.train.demonstrations import ActionNoise, record_demonstrations


class PerEpisodeDecode(InMemoryBCDataset):
    """The cache with each episode's frames asked of LeRobot's decoder (the baseline)."""

    def _decode_videos(
        self, dataset: Any, key: str, rows: dict[int, torch.Tensor], progress: bool
    ) -> dict[int, torch.Tensor]:
        frames = {}
        for ep, ep_rows in rows.items():
            start = float(dataset.meta.episodes[ep][f"videos/{key}/from_timestamp"])
            times = (start + self.columns["timestamp"][ep_rows].double()).tolist()
            path = dataset.root / dataset.meta.get_video_file_path(ep, key)
            chw = decode_video_frames(path, times, dataset.tolerance_s, "pyav", return_uint8=True)
            frames[ep] = self._kept(chw.permute(0, 2, 3, 1))
        return frames


def record(root: Path, episodes: int) -> Path:
    """``episodes`` of the main job's demonstrations (its recording stage's settings)."""
    cfg = load_config("demo", ["progress=false"])
    noise = ActionNoise(**cfg.record.noise)
    return record_demonstrations(cfg.env, root, episodes=episodes, seed=1, noise=noise)


def build(kind: type[InMemoryBCDataset], dataset: Any) -> tuple[float, InMemoryBCDataset]:
    """Seconds to build a cache of ``kind`` at the policy's default size, and the cache."""
    started = time.perf_counter()
    cache = kind(dataset, image_size=(64, 96), progress=False)
    return time.perf_counter() - started, cache


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", type=Path, help="a recorded dataset (default: record one)")
    parser.add_argument("--episodes", type=int, default=16, help="demonstrations to record")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        root = args.dataset or record(Path(scratch) / "demos", args.episodes)
        dataset = open_for_bc(root, video_backend="pyav")
        times: dict[str, list[float]] = {"per_episode": [], "one_pass": []}
        for _ in range(args.repeats):
            seconds, baseline = build(PerEpisodeDecode, dataset)
            times["per_episode"].append(seconds)
            seconds, ours = build(InMemoryBCDataset, dataset)
            times["one_pass"].append(seconds)
        for key in ours.camera_keys:
            if not torch.equal(ours.frames[key], baseline.frames[key]):
                raise SystemExit(f"{key}: the one-pass frames differ from LeRobot's")
        median = {name: statistics.median(values) for name, values in times.items()}
        report = {
            "rows": len(ours),
            "cameras": len(ours.camera_keys),
            "episodes": dataset.meta.total_episodes,
            "seconds_per_episode_decode": round(median["per_episode"], 2),
            "seconds_one_pass": round(median["one_pass"], 2),
            "speedup": round(median["per_episode"] / median["one_pass"], 2),
            "same_frames": True,
        }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
