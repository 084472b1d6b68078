"""The frames-only reward's heads fine-tuned on a LeRobot dataset with crash marks: episodes
recorded as the drive page records them (the embedded world driven, ``next.crash`` set where a
person pressed C), read back into labelled chunks, trained on, and checked."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from oasis_torchrl.config.reward_networks import MotionTrainConfig
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.train.motion import train_motion
from oasis_torchrl.train.motion_chunks import UNLABELLED
from oasis_torchrl.train.motion_dataset import dataset_motion_chunks, episodes_of
from oasis_torchrl.web.recording import EpisodeRecording

CHUNKS = 6


def record(root: Path, marks: list[int | None], crash_column: bool = True) -> None:
    """One episode of ``CHUNKS`` full-throttle chunks per entry of ``marks``: a crash marked at
    that chunk (the episode ends there), or none (saved by stop)."""
    env = OasisEnv("local", 1, all_frames=True, server=ServerConfig(width=96, height=64))
    recording = EpisodeRecording(root, append=True)
    try:
        for mark in marks:
            recording.start()
            td = env.reset()
            for chunk in range(CHUNKS):
                td["action"] = torch.tensor([[[1.0, 0.1 * chunk]] * 4])
                step = env.step(td)
                marked = chunk == mark
                if crash_column:
                    step["next", "crash"] = torch.tensor([[marked]])
                step["next", "done"] = torch.tensor([[marked]])
                if recording.write(step):
                    break
                td = step["next"]
            if recording.recording:
                recording.stop()
    finally:
        env.close()


@pytest.fixture(scope="module")
def marked_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("marked") / "drives"
    record(root, [4, None, 3, None])
    return root


def test_marked_chunks_are_collided_and_the_ones_before_count_down(marked_dataset: Path) -> None:
    chunks = dataset_motion_chunks(marked_dataset, (64, 96), horizon=5, progress=False)
    episodes = episodes_of(chunks)
    assert [len(episode) for episode in episodes] == [5, CHUNKS, 4, CHUNKS]
    assert chunks.frames.shape[1:] == (4, 64, 96, 3) and chunks.frames.dtype == torch.uint8
    first = episodes[0]
    assert first.collided.tolist() == [False] * 4 + [True]
    assert first.time_to.tolist() == [4, 3, 2, 1, UNLABELLED]
    assert not episodes[1].collided.any()
    assert first.actions[2].tolist() == [[1.0, pytest.approx(0.2)]] * 4  # the driven chunk
    assert chunks.progress.isnan().all()  # a person's marks say nothing of progress


def test_train_motion_fine_tunes_on_the_marks_and_checks_the_held_out_episodes(
    marked_dataset: Path, tmp_path: Path
) -> None:
    settings = MotionTrainConfig(
        dataset=str(marked_dataset),
        init_from="small",
        epochs=1,
        batch_size=4,
        validation=0.5,
        output=str(tmp_path / "m.pt"),
        progress=False,
    )
    result = train_motion(settings)
    assert result.path.is_file() and result.chunks == 5 + CHUNKS
    assert math.isfinite(result.validation["collided"])
    checks = result.checks
    assert (checks["episodes"], checks["crashed"]) == (2, 1)
    assert 0.0 <= checks["false_ends"] <= 1.0 and 0.0 <= checks["crashes_seen"] <= 1.0
    assert math.isnan(checks["progress_pearson"])  # no progress labelled


def test_a_dataset_without_marks_is_refused_with_the_fix(tmp_path: Path) -> None:
    root = tmp_path / "unmarked"
    record(root, [None], crash_column=False)
    with pytest.raises(ValueError, match=r"no next\.crash column: record on the drive page"):
        dataset_motion_chunks(root, (64, 96), horizon=5)
