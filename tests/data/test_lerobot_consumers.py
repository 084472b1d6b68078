"""Datasets as LeRobot's consumers see them: BC loading and the dataset viewer.

``lerobot-train`` on the project's dataset is checked in ``tests/lerobot_tools/test_eval_train.py``
(one run serves its tests)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from oasis_torchrl.data import LeRobotRecorder, open_for_bc

from ._fake_env import FakeEnvRun, action


@pytest.fixture(scope="module")
def frame_rows(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two finished episodes (3 and 2 steps) of 64x48 frame rows."""
    root = tmp_path_factory.mktemp("consumers") / "drives"
    with LeRobotRecorder(root, keep_unfinished=False) as recorder:
        recorder.write(FakeEnvRun([[3, 2]]).batch(5))
    return root


def test_open_for_bc_yields_the_next_four_actions(frame_rows: Path) -> None:
    dataset = open_for_bc(frame_rows)
    sample = dataset[5]  # episode 0, step 1, frame row 1
    expected = [action(0, 0, 1, 1), action(0, 0, 1, 2), action(0, 0, 1, 3), action(0, 0, 2, 0)]
    np.testing.assert_array_equal(sample["action"].numpy(), np.stack(expected))
    assert not sample["action_is_pad"].any()
    last = dataset[10]  # episode 0's second-to-last row: two actions left, two padded
    assert last["action_is_pad"].tolist() == [False, False, True, True]
    assert sample["observation.images.front"].shape == (3, 48, 64)


def test_open_for_bc_on_chunk_rows(tmp_path: Path) -> None:
    root = tmp_path / "chunks"
    with LeRobotRecorder(root) as recorder:
        recorder.write(FakeEnvRun([[3]], all_frames=False).batch(3))
    sample = open_for_bc(root, horizon=8)[0]
    assert sample["action"].shape == (2, 8)
    assert sample["action"].reshape(-1, 2)[5].tolist() == action(0, 0, 1, 1).tolist()


def test_dataset_viewer_logs_an_episode(frame_rows: Path, tmp_path: Path) -> None:
    viewer = Path(sys.executable).with_name("lerobot-dataset-viz")
    command = [
        str(viewer),
        "--repo-id=local/drives",
        f"--root={frame_rows}",
        "--episode-index=1",
        "--save=1",
        f"--output-dir={tmp_path}",
        "--batch-size=8",
    ]
    result = subprocess.run(command, capture_output=True, text=True, timeout=240, check=False)
    assert result.returncode == 0, (result.stdout + result.stderr)[-3000:]
    path = tmp_path / "local_drives_episode_1.rrd"
    assert path.is_file() and path.stat().st_size > 10_000
