"""The writer's datasets carry LeRobot's image statistics, kept from level counts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from lerobot.datasets import compute_stats

from oasis_torchrl.compat import CountedImageStats
from oasis_torchrl.data.features import DatasetLayout, build_features
from oasis_torchrl.data.writer import open_dataset, write_episode

from ._readback import open_dataset as read_dataset

LEROBOT_STATS = CountedImageStats.__bases__[0]
"""LeRobot's own class (the writer puts CountedImageStats in its place in LeRobot's module)."""


def _frames(count: int, seed: int) -> np.ndarray:
    """Frames whose range widens and narrows, so the histograms are rebinned on the way."""
    rng = np.random.default_rng(seed)
    bounds = rng.integers(0, 128, (count, 1, 1, 1)), rng.integers(129, 257, (count, 1, 1, 1))
    return (bounds[0] + rng.random((count, 64, 96, 3)) * (bounds[1] - bounds[0])).astype(np.uint8)


def test_counted_statistics_are_lerobots_and_exact_means() -> None:
    frames = _frames(12, seed=3)
    counted, lerobot = CountedImageStats(), LEROBOT_STATS()
    for frame in frames:
        counted.update(frame.reshape(-1, 3))
        lerobot.update(frame.reshape(-1, 3))
    ours, theirs = counted.get_statistics(), lerobot.get_statistics()
    for histogram, expected in zip(counted._histograms, lerobot._histograms, strict=True):
        np.testing.assert_array_equal(histogram, expected)
    for key in ("min", "max", "count", "q01", "q10", "q50", "q90", "q99"):
        np.testing.assert_array_equal(ours[key], theirs[key], err_msg=key)
    pixels = frames.reshape(-1, 3).astype(np.float64)
    np.testing.assert_allclose(ours["mean"], pixels.mean(axis=0), rtol=1e-6)
    np.testing.assert_allclose(ours["std"], pixels.std(axis=0), rtol=1e-6)
    np.testing.assert_allclose(theirs["std"], pixels.std(axis=0), rtol=1e-3)


def test_other_inputs_take_lerobots_update() -> None:
    depth = np.random.default_rng(1).random((500, 1)).astype(np.float32)
    counted, lerobot = CountedImageStats(), LEROBOT_STATS()
    counted.update(depth)
    lerobot.update(depth)
    for key, value in lerobot.get_statistics().items():
        np.testing.assert_array_equal(counted.get_statistics()[key], value)
    with pytest.raises(ValueError, match="image rows of 4 channels after rows of 1"):
        counted.update(np.zeros((10, 4), np.uint8))


def test_a_written_dataset_stores_the_frames_statistics(tmp_path: Path) -> None:
    layout = DatasetLayout(("front",), (64, 96), with_reward=False, with_seed=False)
    dataset = open_dataset(tmp_path / "stats", build_features(layout), 20)
    assert compute_stats.RunningQuantileStats is CountedImageStats
    frames = _frames(30, seed=5)
    rows = [
        {
            "observation.images.front": frame,
            "observation.state": np.zeros(2, np.float32),
            "action": np.zeros(2, np.float32),
            "next.done": np.array([False]),
        }
        for frame in frames
    ]
    write_episode(dataset, rows, "stats")
    dataset.finalize()
    stats = read_dataset(tmp_path / "stats").meta.stats["observation.images.front"]
    pixels = frames.reshape(-1, 3).astype(np.float64) / 255
    np.testing.assert_allclose(np.ravel(stats["mean"]), pixels.mean(axis=0), rtol=1e-5)
    np.testing.assert_allclose(np.ravel(stats["std"]), pixels.std(axis=0), rtol=1e-5)
    np.testing.assert_allclose(np.ravel(stats["min"]), pixels.min(axis=0))
    np.testing.assert_allclose(np.ravel(stats["max"]), pixels.max(axis=0))
