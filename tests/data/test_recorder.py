"""LeRobotRecorder on hand-built env steps: round trip, interruption, append, validation."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
import torch

from oasis_torchrl.config.recording import DEFAULT_CRF
from oasis_torchrl.data import LeRobotRecorder
from oasis_torchrl.data.images import resize_frames
from oasis_torchrl.data.writer import VIDEO_FILE_MB
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, PRIVILEGED_KEY, privileged_state
from oasis_torchrl.sim.config import ServerConfig

from ._fake_env import CAMERAS, FakeEnvRun, action, frame
from ._readback import episodes, expected_frame_rows, open_dataset, psnr

MIN_PSNR = 25.0  # h264, 4:2:0: these 64x48 frames with a sharp block measure ~29-34 dB at crf 30


def _record(root: Path, run: FakeEnvRun, batches: int, horizon: int, **kwargs: object) -> None:
    with LeRobotRecorder(root, **kwargs) as recorder:
        for _ in range(batches):
            recorder.write(run.batch(horizon))


def test_round_trip_keeps_env_rows_apart_and_episodes_whole(tmp_path: Path) -> None:
    root = tmp_path / "drives"
    # Row 0's first episode spans two batches; episodes of different rows end interleaved.
    _record(root, FakeEnvRun([[3, 2], [1, 4], [5]]), batches=3, horizon=2)
    dataset = open_dataset(root)
    stored = episodes(dataset)
    finished = {(0, 0): 3, (1, 0): 1, (0, 1): 2, (1, 1): 4, (2, 0): 5}
    running = {(0, 2): 1, (1, 2): 1, (2, 1): 1}  # saved at close as unfinished
    order = [(1, 0), (0, 0), (0, 1), (1, 1), (2, 0), *running]
    assert [(e.env_row, e.number) for e in stored] == order
    assert dataset.num_episodes == 8 and dataset.fps == 20
    for episode in stored:
        key = (episode.env_row, episode.number)
        steps = finished.get(key) or running[key]
        expected = expected_frame_rows(*key, steps, finished=key in finished)
        assert episode.stop - episode.start == 4 * steps
        for column, values in expected.items():
            np.testing.assert_array_equal(episode.columns[column].reshape(values.shape), values)
    # Frames: lossy video, so closeness, and closer to the right frame than to its neighbour.
    scores = []
    for episode in stored[:3]:
        for offset in range(episode.stop - episode.start):
            sample = dataset[episode.start + offset]
            for camera_index, camera in enumerate(CAMERAS):
                decoded = sample[f"observation.images.{camera}"]
                truth = frame(episode.env_row, episode.number, offset + 3, camera_index)
                neighbour = frame(episode.env_row, episode.number, offset + 4, camera_index)
                scores.append(psnr(decoded, truth))
                assert scores[-1] > psnr(decoded, neighbour)
    logging.getLogger(__name__).info("PSNR min %.1f mean %.1f dB", min(scores), np.mean(scores))
    assert min(scores) > MIN_PSNR


def test_chunk_rows_at_a_quarter_of_the_rate_and_reduced_size(tmp_path: Path) -> None:
    root = tmp_path / "chunks"
    _record(root, FakeEnvRun([[3]], all_frames=False), batches=1, horizon=3, image_size=(24, 32))
    dataset = open_dataset(root)
    assert dataset.fps == 5 and dataset.num_frames == 3
    assert dataset.meta.features["observation.images.front"]["shape"] == (24, 32, 3)
    sample = dataset[2]
    np.testing.assert_array_equal(
        sample["action"].numpy(), np.stack([action(0, 0, 2, k) for k in range(4)]).ravel()
    )
    small = resize_frames(torch.from_numpy(frame(0, 0, 11, 1)), (24, 32)).numpy()
    assert psnr(sample["observation.images.front"], small) > MIN_PSNR - 5
    assert bool(sample["next.done"])


@pytest.mark.parametrize("interruption", [RuntimeError, KeyboardInterrupt])
def test_interrupted_export_keeps_every_completed_episode(
    tmp_path: Path, interruption: type[BaseException]
) -> None:
    root = tmp_path / "interrupted"
    run = FakeEnvRun([[2, 9], [1, 9]])
    with pytest.raises(interruption), LeRobotRecorder(root) as recorder:
        recorder.write(run.batch(3))  # completes (1, 0) and (0, 0); two episodes still running
        raise interruption()
    stored = episodes(open_dataset(root))
    assert [(e.env_row, e.number) for e in stored] == [(1, 0), (0, 0)]
    assert not list(tmp_path.glob(".interrupted-spill-*"))  # spilled frames are cleaned up


def test_append_adds_episodes_and_checks_features(tmp_path: Path) -> None:
    root = tmp_path / "appended"
    _record(root, FakeEnvRun([[1, 2]]), batches=1, horizon=3)
    with pytest.raises(FileExistsError, match="append"):
        _record(root, FakeEnvRun([[1]]), batches=1, horizon=1)
    _record(
        root, FakeEnvRun([[9, 9], [2]]), batches=1, horizon=2, append=True, keep_unfinished=False
    )
    dataset = open_dataset(root)
    assert [len(range(e.start, e.stop)) for e in episodes(dataset)] == [4, 8, 8]
    # small video files: LeRobot remuxes the current file at every saved episode
    assert dataset.meta.info.video_files_size_in_mb == VIDEO_FILE_MB
    assert dataset[16]["episode_index"].item() == 2 and dataset[16]["task"] == "road 1-0"
    with pytest.raises(
        ValueError,
        match=r"images.left_forward: the dataset stores video \(48, 64, 3\), the new rows are",
    ):
        _record(root, FakeEnvRun([[1]]), batches=1, horizon=1, append=True, image_size=(24, 32))


def test_invalid_batches_are_rejected_before_anything_is_written(tmp_path: Path) -> None:
    root = tmp_path / "invalid"
    bad = FakeEnvRun([[1]]).batch(1)
    bad["episode_seed"] = bad["episode_seed"].int()
    message = (
        r"episode_seed: expected int64 rows of shape \(1,\), got int32 of shape \(1, 1, 4, 1\)"
    )
    with LeRobotRecorder(root) as recorder:
        with pytest.raises(TypeError, match=message):
            recorder.write(bad)
        assert not root.exists()  # a bad first batch creates nothing
        recorder.write(FakeEnvRun([[1]]).batch(1))
        with pytest.raises(TypeError, match=message):
            recorder.write(bad)
        smaller = FakeEnvRun([[1]], size=(24, 32)).batch(1)
        with pytest.raises(
            ValueError, match=r"\('pixels', 'left_forward'\): expected 48x64 frames"
        ):
            recorder.write(smaller)
        with pytest.raises(ValueError, match="2 env rows, earlier batches had 1"):
            recorder.write(FakeEnvRun([[1], [1]]).batch(1))
    assert open_dataset(root).num_episodes == 1


def test_max_episodes_and_a_missed_episode_boundary(tmp_path: Path, caplog) -> None:
    root = tmp_path / "limited"
    first = FakeEnvRun([[9]]).batch(2)  # episode (0, 0) still running...
    later = FakeEnvRun([[1, 9]])
    later.batch(1)
    switched = later.batch(2)  # ... then rows of episode (0, 1) arrive without a done flag
    with LeRobotRecorder(root, max_episodes=3) as recorder:
        recorder.write(first)
        with caplog.at_level(logging.WARNING):
            recorder.write(switched)
        assert "without a done flag" in caplog.text
        assert recorder.episodes_written == 1 and recorder.running_episodes == 1
        recorder.end_episodes()  # e.g. a fixed-length evaluation that stops here
        assert recorder.episodes_written == 2 and recorder.running_episodes == 0
        recorder.write(FakeEnvRun([[1, 1]]).batch(2))  # one more, then full
        assert recorder.full and recorder.rows_written == 8 + 8 + 4
    stored = [(e.env_row, e.number) for e in episodes(open_dataset(root))]
    assert stored == [(0, 0), (0, 1), (0, 0)]


def test_long_episodes_spill_to_disk_and_come_back_whole(tmp_path: Path) -> None:
    root = tmp_path / "spilled"
    run = FakeEnvRun([[3], [2]])
    with LeRobotRecorder(root, buffer_bytes=50_000) as recorder:  # every episode spills
        recorder.write(run.batch(3))
        spilled = list(tmp_path.glob(".spilled-spill-*/episode-*"))
        assert len(spilled) == 1  # episode (1, 1), still running; the ended two are written
    dataset = open_dataset(root)
    stored = episodes(dataset)
    lengths = [(e.env_row, e.number, e.stop - e.start) for e in stored]
    assert lengths == [(1, 0, 8), (0, 0, 12), (1, 1, 4)]
    assert not spilled[0].exists()
    for episode in stored[:2]:
        expected = expected_frame_rows(
            episode.env_row, 0, (episode.stop - episode.start) // 4, True
        )
        np.testing.assert_array_equal(episode.columns["action"], expected["action"])
    sample = dataset[stored[1].start + 9]
    assert psnr(sample["observation.images.right_forward"], frame(0, 0, 12, 2)) > MIN_PSNR


def test_the_privileged_state_of_each_frame_is_stored(tmp_path: Path) -> None:
    """Each row's ``privileged_state`` is the ground truth of that row's frame: row ``4t`` the
    previous chunk's last frame, row ``4t+j`` frame ``j-1`` of the chunk (the image rule)."""
    env = OasisEnv(
        "local", num_envs=1, prompts="urban", server=ServerConfig(width=48, height=32),
        all_frames=True, max_steps=3,
    )  # fmt: skip
    try:
        env.set_seed(4)
        rollout = env.rollout(3, lambda td: td.set("action", torch.full((1, 4, 2), 0.7)))
    finally:
        env.close()
    root = tmp_path / "privileged"
    with LeRobotRecorder(root, privileged=True) as recorder:
        assert recorder.write(rollout) == 1
    stored = np.stack(open_dataset(root).hf_dataset[PRIVILEGED_KEY])
    truth = {field: rollout["next", "truth", field][0] for field in PRIVILEGED_FIELDS}
    after = privileged_state(truth)  # [3 steps, 4 frames, 6]
    first = privileged_state({f: rollout["truth", f][0, 0, -1] for f in PRIVILEGED_FIELDS})
    expected = torch.cat([first[None], after.flatten(0, 1)[:-1]])  # the frame before each action
    np.testing.assert_allclose(stored, expected.numpy(), rtol=1e-6)
    assert stored.shape == (12, len(PRIVILEGED_FIELDS)) and np.ptp(stored[:, 0]) > 0  # it moved
    with pytest.raises(KeyError, match=r"'truth', 'speed'\) \(the ground truth"):
        LeRobotRecorder(tmp_path / "none", privileged=True).write(rollout.exclude("truth"))


def test_the_stored_video_has_the_quality_asked_for(tmp_path: Path) -> None:
    run = FakeEnvRun([[2]])
    scores = {}
    for crf in (DEFAULT_CRF, 40):
        root = tmp_path / f"crf{crf}"
        _record(root, run, batches=1, horizon=2, crf=crf)
        dataset = open_dataset(root)
        assert dataset.meta.features["observation.images.front"]["info"]["video.crf"] == crf
        scores[crf] = np.mean(
            [
                psnr(dataset[row]["observation.images.front"], frame(0, 0, row + 3, 1))
                for row in range(8)
            ]
        )
    assert scores[DEFAULT_CRF] > scores[40] + 3, scores


def test_a_crf_outside_the_codec_range_fails_before_anything_is_written(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"crf 60 is outside h264's range \[0, 51\]"):
        LeRobotRecorder(tmp_path / "drives", crf=60)
    assert not (tmp_path / "drives").exists()
