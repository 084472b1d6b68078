"""Importing human recordings (the reference SDK's layout) into LeRobot datasets."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from oasis_torchrl.cli import main
from oasis_torchrl.data import RecordingError, import_recordings
from oasis_torchrl.data.importer import read_manifest

from ._fake_env import CAMERAS, SIZE, frame
from ._readback import episodes, open_dataset, psnr


def _action(episode: int, step: int) -> list[list[float]]:
    if step == 0:
        return [[0.0, 0.0]] * 4  # the driver waits before setting off
    return [[0.1 * k + 0.05 * step, (episode % 3 - 1) * 0.1 * k] for k in range(4)]


def _write_episode(source: Path, episode: int, steps: int) -> Path:
    """An episode folder as the reference recorder writes it (RGBA PNGs)."""
    folder = source / f"episode_{episode}"
    (folder / "frames").mkdir(parents=True)
    lines = []
    for step in range(steps):
        record: dict[str, object] = {"action": _action(episode, step)}
        for index, camera in enumerate(CAMERAS):
            relative = f"frames/{step:06d}_{camera}.png"
            rgba = np.dstack([frame(0, episode, step, index), np.full(SIZE, 255, np.uint8)])
            Image.fromarray(rgba, "RGBA").save(folder / relative)
            record[f"frame_{camera}"] = relative
        lines.append(json.dumps(record))
    (folder / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    return folder


@pytest.fixture
def recordings(tmp_path: Path) -> Path:
    """Episodes 1-3 good; 4-7 broken in the four ways recordings break."""
    source = tmp_path / "recordings"
    for episode in range(1, 8):
        _write_episode(source, episode, steps=4)
    (source / "episode_4" / "frames" / "000002_front.png").unlink()
    Image.new("RGBA", (32, 24)).save(source / "episode_5" / "frames" / "000001_left_forward.png")
    manifest = source / "episode_6" / "manifest.jsonl"
    lines = manifest.read_text().splitlines()
    lines[3] = json.dumps({**json.loads(lines[3]), "action": [[0.5, 0.0]] * 3})
    manifest.write_text("\n".join(lines) + "\n")
    manifest = source / "episode_7" / "manifest.jsonl"
    lines = manifest.read_text().splitlines()
    lines[1] = lines[1][:20]
    manifest.write_text("\n".join(lines) + "\n")
    return source


def test_bad_episodes_are_reported_and_skipped(recordings: Path, tmp_path: Path) -> None:
    root = tmp_path / "human"
    report = import_recordings(recordings, root, source_size=SIZE)
    assert [path.name for path in report.imported] == ["episode_1", "episode_2", "episode_3"]
    problems = {error.path.parent.name: (error.line, error.reason) for error in report.skipped}
    assert problems["episode_4"] == (3, "missing frame file frames/000002_front.png")
    assert problems["episode_5"][0] == 2 and "is 32x24, expected 64x48" in problems["episode_5"][1]
    assert problems["episode_6"] == (4, "action must have shape (4, 2), got (3, 2)")
    assert problems["episode_7"][0] == 2 and problems["episode_7"][1].startswith("broken JSON")
    assert all(str(error).startswith(str(recordings)) for error in report.skipped)
    dataset = open_dataset(root)
    assert dataset.fps == 5 and dataset.num_episodes == 3 and report.rows == 12
    stored = episodes(dataset)
    assert [e.task for e in stored] == ["human driving"] * 3
    second = stored[1]
    np.testing.assert_allclose(second.columns["action"][2], np.ravel(_action(2, 2)), atol=0)
    np.testing.assert_allclose(second.columns["observation.state"][2], _action(2, 1)[-1])
    assert second.columns["next.done"].tolist() == [False, False, False, True]
    sample = dataset[second.start + 3]
    assert psnr(sample["observation.images.right_forward"], frame(0, 2, 3, 2)) > 25.0
    assert "next.reward" not in dataset.features and "episode_seed" not in dataset.features


def test_drop_idle_reduced_size_and_append(recordings: Path, tmp_path: Path) -> None:
    root = tmp_path / "human"
    first = import_recordings(
        recordings, root, source_size=SIZE, drop_idle=True, image_size=(24, 32)
    )
    again = import_recordings(
        recordings, root, source_size=SIZE, drop_idle=True, image_size=(24, 32), append=True
    )
    assert first.rows == again.rows == 9  # the idle first step of each good episode is gone
    dataset = open_dataset(root)
    assert dataset.num_episodes == 6
    assert dataset[0]["observation.images.front"].shape == (3, 24, 32)
    assert dataset[0]["observation.state"].tolist() == [0.0, 0.0]


def test_import_cli_exit_codes(recordings: Path, tmp_path: Path) -> None:
    args = ["import-recordings", str(recordings), "--source-size", "48x64"]
    assert main([*args, "--root", str(tmp_path / "cli")]) == 1  # some episodes skipped
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["import-recordings", str(empty), "--root", str(tmp_path / "none")]) == 2
    (recordings / "episode_1" / "manifest.jsonl").unlink()
    with pytest.raises(RecordingError, match=r"episode_1/manifest.jsonl: missing file"):
        read_manifest(recordings / "episode_1")
