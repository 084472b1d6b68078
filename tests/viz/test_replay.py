"""``oasis-torchrl view``: saved rollouts and LeRobot datasets to .rrd, read back with rerun."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from oasis_torchrl.cli import main
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.protocol import API_KEY_ENV_VAR
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.viz.replay import load_rollout, save_rollout, source_kind

from ._readback import Readback, blueprint_views, printed
from ._rollouts import CAMERAS, color, rollout

DATASET_CAMERAS = ("left_forward", "front")
EPISODE_FRAMES = 6
VIDEO_TOLERANCE = 8  # levels: h264 (crf 30, 4:2:0) of flat colours


def _dataset_color(episode: int, frame: int, camera: int) -> tuple[int, int, int]:
    return (40 + 60 * episode, 30 + 30 * frame, 50 + 100 * camera)


def _dataset_action(episode: int, frame: int) -> list[float]:
    return [0.1 * frame, -0.2 * episode]


@pytest.fixture(scope="module")
def dataset_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A LeRobot dataset of 2 episodes x 6 frames, written by LeRobot itself."""
    from lerobot.configs.video import RGBEncoderConfig
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = tmp_path_factory.mktemp("lerobot") / "drives"
    image = {"dtype": "video", "shape": (48, 64, 3), "names": ["height", "width", "channels"]}
    pair = {"dtype": "float32", "shape": (2,), "names": ["throttle", "steering"]}
    features = {f"observation.images.{camera}": image for camera in DATASET_CAMERAS}
    features |= {"observation.state": pair, "action": pair}
    features["next.reward"] = {"dtype": "float32", "shape": (1,), "names": None}
    features["next.done"] = {"dtype": "bool", "shape": (1,), "names": None}
    features["episode_seed"] = {"dtype": "int64", "shape": (1,), "names": None}
    dataset = LeRobotDataset.create(
        "local/drives",
        fps=20,
        features=features,
        root=root,
        video_backend="pyav",
        rgb_encoder=RGBEncoderConfig(vcodec="h264"),
    )
    try:
        for episode in range(2):
            for frame in range(EPISODE_FRAMES):
                row = {
                    f"observation.images.{camera}": np.full(
                        (48, 64, 3), _dataset_color(episode, frame, index), np.uint8
                    )
                    for index, camera in enumerate(DATASET_CAMERAS)
                }
                row["observation.state"] = np.zeros(2, np.float32)
                row["action"] = np.array(_dataset_action(episode, frame), np.float32)
                row["next.reward"] = np.array([frame + episode], np.float32)
                row["next.done"] = np.array([frame == EPISODE_FRAMES - 1])
                row["episode_seed"] = np.array([100 + episode])
                dataset.add_frame(row | {"task": f"task {episode}"})
            dataset.save_episode(parallel_encoding=False)  # no process pool: fast tests
    finally:
        dataset.finalize()
    return root


def test_dataset_episode_to_rrd(dataset_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "episode.rrd"
    assert main(["view", str(dataset_root), "--episodes", "1", "--save", str(out)]) == 0
    readback = Readback(out)

    expected = {f"episode/1/camera/{camera}" for camera in DATASET_CAMERAS}
    expected |= {f"episode/1/action/{name}" for name in ("throttle", "steering")}
    expected |= {f"episode/1/state/{name}" for name in ("throttle", "steering")}
    assert readback.entities() == expected | {"episode/1/reward/total", "episode/1/events"}
    for index, camera in enumerate(DATASET_CAMERAS):
        frames, images = readback.images(f"episode/1/camera/{camera}")
        assert frames == list(range(EPISODE_FRAMES))
        for frame, image in enumerate(images):
            error = np.abs(image.astype(int) - _dataset_color(1, frame, index)).mean()
            assert error <= VIDEO_TOLERANCE
    frames, throttle = readback.scalars("episode/1/action/throttle")
    assert frames == list(range(EPISODE_FRAMES))
    np.testing.assert_allclose(throttle, [_dataset_action(1, f)[0] for f in frames], atol=1e-6)
    np.testing.assert_allclose(readback.scalars("episode/1/action/steering")[1], [-0.2] * 6)
    np.testing.assert_allclose(readback.scalars("episode/1/reward/total")[1], range(1, 7))
    assert readback.texts("episode/1/events") == (
        [0, 5],
        ["episode 1 starts: 'task 1', seed 101", "episode 1 ends"],
    )
    steps, _ = readback.column("episode/1/reward/total", "Scalars:scalars", index="step")
    assert steps == [0, 1]  # a 20 fps dataset: a row per frame, frames 0-3 are step 0
    # Every panel is titled with the dataset's name (there is no policy)
    front = (f"{dataset_root.name}: front", "episode/1/camera/front")
    assert ("2D", *front) in blueprint_views(out)
    assert "[episode 1]" in printed(out)  # the tab, named after its episode
    seconds, _ = readback.column("episode/1/reward/total", "Scalars:scalars", index="sim_time")
    assert [s.total_seconds() for s in seconds] == pytest.approx([f / 20 for f in range(6)])


def test_saved_rollout_rows_to_rrd(tmp_path: Path) -> None:
    folder = save_rollout(rollout(3, 3, {2: [0]}), tmp_path / "run")
    assert source_kind(folder) == "rollout" and load_rollout(folder).batch_size == (3, 3)
    out = tmp_path / "rollout.rrd"
    assert main(["view", str(folder), "--rows", "2", "--save", str(out)]) == 0
    readback = Readback(out)

    rows = {entity.split("/")[1] for entity in readback.entities() if entity.startswith("env/")}
    assert rows == {"2"}
    table = readback.static("summary/table", "TextDocument:text")[0]
    line = "| 0 | 2 | road 2-0 | 200 | env | **collision (hit an obstacle)** at step 1, return 2.00"
    assert f"{line}, frames 0-7 |" in table
    frames, images = readback.images("env/2/camera/front")
    assert frames == [3, 7, 11, 15, 19]  # reset, step 0 (crash), reset, steps 1-2
    resets = [True, False, True, False, False]
    steps = [0, 0, 1, 1, 2]
    for image, t, reset in zip(images, steps, resets, strict=True):
        assert np.abs(image.astype(int) - color(2, t, CAMERAS.index("front"), reset)).max() <= 4
    assert readback.texts("env/2/events")[1][-1] == "episode 1 starts: 'road 2-1', seed 201"
    assert ("TextLog", "run: events", "env/2/events") in blueprint_views(out)  # the rollout's name
    with pytest.raises(FileExistsError):
        save_rollout(rollout(1, 1), folder)


def test_saved_rollout_gets_its_roads_from_a_server_it_is_pointed_at(
    tmp_path: Path, local_server: LocalServer, monkeypatch: pytest.MonkeyPatch
) -> None:
    env = OasisEnv("local", 1, "rural road", server=ServerConfig(width=48, height=32, processes=0))
    folder = save_rollout(env.rollout(3), tmp_path / "run")
    env.close()
    monkeypatch.setenv(API_KEY_ENV_VAR, local_server.api_key)
    roads = {}
    for name, flags in {"alone": [], "server": ["--scenes", local_server.endpoint]}.items():
        out = tmp_path / f"{name}.rrd"
        assert main(["view", str(folder), "--save", str(out), *flags]) == 0
        readback = Readback(out)
        assert readback.column("env/0/topdown/car", "LineStrips2D:strips")[1]  # always drawn
        roads[name] = readback.column("env/0/topdown/road", "LineStrips2D:strips")[1]
    assert not any(roads["alone"]) and any(roads["server"])


def test_bad_paths_and_choices_exit_with_2(dataset_root: Path, tmp_path: Path) -> None:
    recording = tmp_path / "run.rrd"
    folder = save_rollout(rollout(1, 1), tmp_path / "run")
    assert main(["view", str(folder), "--save", str(recording)]) == 0
    assert main(["view", str(recording), "--save", str(tmp_path / "copy.rrd")]) == 2
    assert main(["view", str(tmp_path / "missing")]) == 2
    assert main(["view", str(tmp_path)]) == 2  # a folder that is none of the three
    assert main(["view", str(dataset_root), "--episodes", "7", "--save", str(recording)]) == 2
    assert main(["view", str(folder), "--save", str(tmp_path / "out.txt")]) == 2
    for flags in (["--rows", "x"], ["--jpeg-quality", "0"], ["--save", "a.rrd", "--connect", "x"]):
        assert main(["view", str(folder), *flags]) == 2
