"""RolloutLogger: write recordings every way in, read them back with rerun's reader and CLI."""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from torchrl.collectors import Collector

from oasis_torchrl.cli import main
from oasis_torchrl.client import A2VClient
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.viz import LogOptions, RerunFrameConsumer, RerunTransform, RolloutLogger

from ._readback import (
    Readback,
    RrdReader,
    blueprint_count,
    blueprint_views,
    chunk_paths,
    printed,
)
from ._rollouts import CAMERAS, SIZE, TERMS, action, color, reward, rollout

FPS = 20.0
JPEG_TOLERANCE = 4  # levels; flat colours survive JPEG almost exactly


def _log(path: Path, td, **options: object) -> Readback:
    with RolloutLogger(path, LogOptions(**options)) as rerun_logger:
        rerun_logger.log_rollout(td)
    return Readback(path)


def _row_entities(row: int) -> set[str]:
    base = f"env/{row}"
    entities = {f"{base}/camera/{camera}" for camera in CAMERAS}
    entities |= {f"{base}/action/{name}" for name in ("throttle", "steering")}
    entities |= {f"{base}/reward/{name}" for name in ("total", *TERMS)}
    truth = set(LogOptions().truth_series) - {"lateral_offset"}  # not in the hand-built truth
    entities |= {f"{base}/truth/{name}" for name in truth}
    layers = ("road", "lanes", "obstacles", "path", "car", "scale")
    entities |= {f"{base}/topdown/{layer}" for layer in layers}
    return entities | {f"{base}/events"}


SUMMARY = {"summary/table", "summary/env"}


def test_rollout_entities_frames_values_and_timelines(tmp_path: Path) -> None:
    # Row 1 crashes at step t=1 (4 steps, rows 0 and 1 of 3 logged): its next episode's reset
    # takes one tick of its own. Ticks: 0 reset, 1-2 steps, 3 reset of row 1, 4-5 steps.
    readback = _log(tmp_path / "run.rrd", rollout(3, 4, {1: [1]}), rows=(0, 1))

    marks = {"env/1/collision/speed", "env/1/collision/obstacle_distance"}
    assert readback.entities() == _row_entities(0) | _row_entities(1) | SUMMARY | marks
    assert {"frame", "step", "sim_time"} <= readback.timelines()
    steps, _ = readback.column("env/1/reward/total", "Scalars:scalars", index="step")
    assert steps == [1, 2, 4, 5]  # frame // 4
    image_frames = {0: [3, 7, 11, 19, 23], 1: [3, 7, 11, 15, 19, 23]}
    image_steps = {0: [(0, True), (0, False), (1, False), (2, False), (3, False)]}
    image_steps[1] = [(0, True), (0, False), (1, False), (2, True), (2, False), (3, False)]
    for row in (0, 1):
        for index, camera in enumerate(CAMERAS):
            frames, images = readback.images(f"env/{row}/camera/{camera}")
            assert frames == image_frames[row]
            for image, (t, reset) in zip(images, image_steps[row], strict=True):
                assert image.shape == (*SIZE, 3)  # as served: the viewer scales it
                error = np.abs(image.astype(int) - color(row, t, index, reset)).max()
                assert error <= JPEG_TOLERANCE

    step_frames = [4, 5, 6, 7, 8, 9, 10, 11, 16, 17, 18, 19, 20, 21, 22, 23]
    frames, throttle = readback.scalars("env/1/action/throttle")
    _, steering = readback.scalars("env/1/action/steering")
    assert frames == step_frames
    expected = [action(1, t, k) for t in range(4) for k in range(4)]
    np.testing.assert_allclose(throttle, [a[0] for a in expected], atol=1e-6)
    np.testing.assert_allclose(steering, [a[1] for a in expected], atol=1e-6)
    frames, rewards = readback.scalars("env/1/reward/total")
    assert frames == [7, 11, 19, 23]
    np.testing.assert_allclose(rewards, [reward(1, t) for t in range(4)], atol=1e-6)
    assert readback.scalars("env/0/reward/collision_risk")[1] == [0.5] * 4
    frames, distance = readback.scalars("env/0/truth/obstacle_distance")
    assert len(frames) == 4 * 5 and np.isnan(distance).all()  # inf is logged as "no value"
    seconds, _ = readback.column("env/0/reward/total", "Scalars:scalars", index="sim_time")
    assert [s.total_seconds() for s in seconds] == pytest.approx([f / FPS for f in [7, 11, 19, 23]])

    frames, texts = readback.texts("env/1/events")
    assert frames == [0, 11, 12]  # the end is on the last frame of the episode's last step
    assert texts == [
        "episode 1 starts: 'road 1-0', seed 100",
        "episode 1 ends: collision (hit an obstacle) after 2 steps, return 2.100",
        "episode 2 starts: 'road 1-1', seed 101",
    ]
    assert readback.scalars("env/1/collision/speed") == ([10], [2.0])  # the collision's frame
    colors = readback.column("env/1/topdown/car", "LineStrips2D:colors")[1]
    assert [c[0] for c in colors] == [0xFFFFFFFF] * 2 + [0xFF2828FF] + [0xFFFFFFFF] * 3


def test_default_blueprint_has_a_layout_per_logged_row(tmp_path: Path) -> None:
    path = tmp_path / "run.rrd"
    _log(path, rollout(3, 2, {2: [1]}), rows=(0, 2))
    views = blueprint_views(path)
    # One unit per plot; a plot only where its signal is known (no lateral offset here)
    plots = ["actions (-1 to 1)", "reward", "collision risk (depth, 0 to 1)"]
    plots += ["distance to obstacle ahead (m)", "speed (m/s)"]
    for row in (0, 2):
        assert {("2D", camera, f"env/{row}/camera/{camera}") for camera in CAMERAS} <= views
        assert ("2D", "top-down", f"env/{row}/topdown") in views
        assert ("TextLog", "events", f"env/{row}/events") in views
        assert {("TimeSeries", plot, f"env/{row}") for plot in plots} <= views
        assert ("TimeSeries", "lateral offset (m)", f"env/{row}") not in views
    assert not any(origin.startswith("env/1") for _, _, origin in views)
    # Row 2's episode ended: the summary tab appeared
    assert ("TextDocument", "episodes", "summary/table") in views
    chart = "env: distance driven in m (or return) by episode number"
    assert ("BarChart", chart, "summary/env") in views
    text = printed(path)
    assert "TimePanelBlueprint:play_state" in text  # opens at the start, playing
    assert "TimePanelBlueprint:loop_mode" in text  # and back to the start from the end
    # Tabs are named after their episodes (row 0's still runs); a file gets one layout, at close
    assert "[episode 0: running]" in text and "[episode 1: collision at step 2]" in text
    assert blueprint_count(path) == 1
    order = chunk_paths(path)  # the layout first, then the summary, then the episodes
    assert order[0].startswith(("/view/", "/container/", "/viewport"))
    summary = next(i for i, p in enumerate(order) if p.startswith("/summary/"))
    assert summary < next(i for i, p in enumerate(order) if p.startswith("/env/"))


def test_an_evaluation_of_one_policy_titles_every_panel_with_it(tmp_path: Path) -> None:
    """``oasis-torchrl eval ... rerun=FILE`` without ``compare``: every panel of the layout read
    back from the file names the policy, as side by side."""
    path = tmp_path / "alone.rrd"
    policy = "constant:throttle=1.0,steering=0.0"
    settings = ["episodes=1", "max_steps=3", "env.image_size=[64,96]", "progress=false"]
    assert main(["eval", f"policy={policy}", *settings, f"rerun={path}"]) == 0
    views = blueprint_views(path)
    kinds = {kind for kind, _, _ in views}
    assert kinds == {"2D", "TimeSeries", "TextLog", "BarChart", "TextDocument"}
    unnamed = sorted(name for _, name, _ in views if not name.startswith(f"{policy}: "))
    assert not unnamed, f"panels without the policy's name: {unnamed}"
    assert ("2D", f"{policy}: front", "env/0/camera/front") in views
    assert ("2D", f"{policy}: top-down", "env/0/topdown") in views
    assert ("TimeSeries", f"{policy}: speed (m/s)", "env/0") in views


def test_all_frames_raw_images_and_depth(tmp_path: Path) -> None:
    td = rollout(1, 2, all_frames=True, depth=True)
    readback = _log(tmp_path / "raw.rrd", td, jpeg_quality=None, all_frames=True, background=False)

    frames, buffers = readback.column("env/0/camera/front", "Image:buffer")
    assert frames == list(range(12))  # 3 ticks x 4 frames
    first = np.frombuffer(bytes(buffers[0][0]), np.uint8).reshape(*SIZE, 3)
    assert (first == color(0, 0, 1, reset=True)).all()
    frames, depths = readback.column("env/0/depth/front", "DepthImage:buffer")
    assert frames == [3, 7, 11]
    depth = np.frombuffer(bytes(depths[0][0]), np.float16).reshape(SIZE)
    assert (depth[0] == 0).all() and (depth[1:] == 7.5).all()  # sky (inf) -> 0: "no depth"


def test_collector_hook_continues_episodes_across_batches(tmp_path: Path) -> None:
    full = rollout(2, 6, {0: [2]})
    whole = _log(tmp_path / "whole.rrd", full)
    with RolloutLogger(tmp_path / "batches.rrd") as rerun_logger:
        assert rerun_logger(full[:, :3]) is not None
        rerun_logger(full[:, 3:])
    batches = Readback(tmp_path / "batches.rrd")

    for row in (0, 1):
        assert (
            batches.images(f"env/{row}/camera/front")[0]
            == (whole.images(f"env/{row}/camera/front")[0])
        )
        assert batches.texts(f"env/{row}/events") == whole.texts(f"env/{row}/events")
    assert batches.texts("env/0/events")[0] == [0, 15, 16]  # start, end (a collision), start
    assert batches.images("env/1/camera/front")[0] == [3, 7, 11, 15, 23, 27, 31]


def test_postproc_hook_of_a_real_collector(tmp_path: Path) -> None:
    small = ServerConfig(width=64, height=48)
    env = OasisEnv("local", num_envs=2, prompts="highway", server=small, max_steps=3)
    with RolloutLogger(tmp_path / "collector.rrd") as rerun_logger:
        collector = Collector(
            env, policy=None, frames_per_batch=8, total_frames=16, postproc=rerun_logger
        )
        try:
            batches = list(collector)
        finally:
            collector.shutdown()
    readback = Readback(tmp_path / "collector.rrd")

    assert len(batches) == 2
    for row in (0, 1):
        _, texts = readback.texts(f"env/{row}/events")
        assert sum("starts" in t for t in texts) == 3  # 8 steps, episodes of 3 steps
        assert sum("ends: time limit after 3 steps" in t for t in texts) == 2
        frames, rewards = readback.scalars(f"env/{row}/reward/total")
        assert len(frames) == 8
        logged = torch.cat([b["next", "reward"][row].flatten() for b in batches]).numpy()
        np.testing.assert_allclose(rewards, logged, atol=1e-6)
        assert len(readback.images(f"env/{row}/camera/front")[0]) == 8 + 3


def test_transform_on_a_real_env_matches_the_rollout_function(tmp_path: Path) -> None:
    env = OasisEnv(
        "local",
        num_envs=2,
        prompts=["urban street", "rural road"],
        server=ServerConfig(width=96, height=64),
        max_steps=2,
    )
    with RolloutLogger(tmp_path / "transform.rrd") as rerun_logger:
        env = env.append_transform(RerunTransform(rerun_logger))
        td = env.rollout(5, break_when_any_done=False)
    env.close()
    live = Readback(tmp_path / "transform.rrd")
    replayed = _log(tmp_path / "function.rrd", td)

    for row in (0, 1):
        frames, _ = live.images(f"env/{row}/camera/front")
        assert len(frames) == 3 + 5  # 3 episode starts, 5 steps
        _, texts = live.texts(f"env/{row}/events")
        assert sum("starts" in t for t in texts) == 3
        assert sum("ends: time limit after 2 steps" in t for t in texts) == 2
        assert any(f"'{['urban street', 'rural road'][row]}'" in t for t in texts)
        _, rewards = live.scalars(f"env/{row}/reward/total")
        np.testing.assert_allclose(rewards, td["next", "reward"][row].flatten().numpy(), atol=1e-6)
        _, speed = live.scalars(f"env/{row}/truth/speed")
        assert max(speed) >= 0
        for entity in (f"env/{row}/camera/front", f"env/{row}/reward/total", f"env/{row}/events"):
            component = {"camera": "EncodedImage:blob", "reward": "Scalars:scalars"}.get(
                entity.split("/")[2], "TextLog:text"
            )
            assert live.column(entity, component) == replayed.column(entity, component)
        # The transform gave the logger its env's scene source: the road is drawn
        road = live.column(f"env/{row}/topdown/road", "LineStrips2D:strips")[1]
        lanes = live.column(f"env/{row}/topdown/lanes", "LineStrips2D:strips")[1]
        assert any(road) and any(len(strips) >= 4 for strips in lanes)  # edges and lane lines


def test_frame_consumer_of_the_sync_client(tmp_path: Path, local_server: LocalServer) -> None:
    # Every frame of a chunk (all_frames), at the sent size, to compare pixel by pixel
    with RolloutLogger(tmp_path / "client.rrd", LogOptions(all_frames=True)) as rerun_logger:
        client = A2VClient(
            local_server.endpoint,
            api_key=local_server.api_key,
            frame_consumer=RerunFrameConsumer(rerun_logger, row=3),
        )
        with client:
            client.initialize()
            client.prompt("urban street", seed=1)
            first = client.infer([[0.5, 0.0]] * 4)
            client.infer([[0.5, 0.1]] * 4)
            client.prompt("rural road", seed=2)
            client.infer([[0.2, 0.0]] * 4)
    readback = Readback(tmp_path / "client.rrd")

    assert readback.entities() == {f"env/3/camera/{c}" for c in CAMERAS} | {"env/3/events"}
    frames, images = readback.images("env/3/camera/front")
    assert frames == list(range(12))
    for logged, sent in zip(images, first.frames["front"], strict=False):
        assert np.abs(logged.astype(int) - sent.astype(int)).mean() < 6
    assert readback.texts("env/3/events") == (
        [0, 8],
        ["episode 0 starts (new clip)", "episode 1 starts (new clip)"],
    )


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_live_viewer_over_grpc(tmp_path: Path) -> None:
    """A headless rerun server stands in for the viewer: it saves what it receives."""
    port, received = _free_port(), tmp_path / "received.rrd"
    command = [sys.executable, "-m", "rerun", "--bind", "127.0.0.1", "--port", str(port)]
    # Its own process group: `python -m rerun` runs the server binary as a child process.
    server = subprocess.Popen(
        [*command, "--save", str(received), "--memory-limit", "100MB"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        _wait_for_port(port)
        with RolloutLogger(f"rerun+http://127.0.0.1:{port}/proxy") as rerun_logger:
            rerun_logger.log_rollout(rollout(2, 2))
        _wait_for_entities(received, "env/1/camera/front", count=3)
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(timeout=10)
    readback = Readback(received)  # complete once the server has stopped
    expected = [reward(1, t) for t in range(2)]
    assert readback.scalars("env/1/reward/total")[1] == pytest.approx(expected)


def _wait_for_port(port: int, timeout: float = 20.0) -> None:
    import socket
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket() as sock:
            if sock.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise AssertionError(f"rerun server did not listen on port {port}")


def _wait_for_entities(path: Path, entity: str, count: int, timeout: float = 20.0) -> None:
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            try:
                if len(Readback(path).images(entity)[0]) == count:
                    return
            except Exception:  # the file is still being written
                pass
        time.sleep(0.2)
    raise AssertionError(f"{entity} did not arrive {count} times in {path}")


def test_two_loggers_keep_their_own_recordings(tmp_path: Path) -> None:
    td = rollout(2, 2)
    with (
        RolloutLogger(tmp_path / "a.rrd", LogOptions(rows=(0,))) as first,
        RolloutLogger(tmp_path / "b.rrd", LogOptions(rows=(1,))) as second,
    ):
        first.log_rollout(td)
        second.log_rollout(td)
    assert {e.split("/")[1] for e in Readback(tmp_path / "a.rrd").entities()} == {"0"}
    assert {e.split("/")[1] for e in Readback(tmp_path / "b.rrd").entities()} == {"1"}


def test_bad_input_is_named(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="jpeg_quality"):
        LogOptions(jpeg_quality=101)
    with pytest.raises(ValueError, match="must be 'spawn', a gRPC URL"):
        RolloutLogger(tmp_path / "out.txt")
    with RolloutLogger(tmp_path / "bad.rrd", LogOptions(rows=(5,))) as rerun_logger:
        with pytest.raises(ValueError, match=r"rows \(5,\) exceed the 2 env rows"):
            rerun_logger.log_rollout(rollout(2, 1))
        with pytest.raises(TypeError, match="cannot be pickled"):
            pickle.dumps(rerun_logger)
    td = rollout(2, 1)
    td["next", "pixels", "front"] = td["next", "pixels", "front"].float()
    with RolloutLogger(tmp_path / "bad2.rrd") as rerun_logger:
        with pytest.raises(TypeError, match=r"\('pixels', 'front'\) must be uint8"):
            rerun_logger.log_rollout(td)
        with pytest.raises(ValueError, match=r"batch size \[N, T\]"):
            rerun_logger.log_rollout(td.unsqueeze(0))
        with pytest.raises(ValueError, match=r"reset rows \[7\]"):
            rerun_logger.log_reset(td[:, 0], rows=[7])
    with (
        pytest.raises(ValueError, match="action must be"),
        RolloutLogger(tmp_path / "bad3.rrd") as rerun_logger,
    ):
        rerun_logger.log_step(td[:, 0]["next"].exclude("pixels"), torch.zeros(2, 3))


def test_a_logger_left_open_is_closed_at_exit(tmp_path: Path) -> None:
    out = tmp_path / "open.rrd"
    script = (
        f"import sys; sys.path.insert(0, {str(Path(__file__).parents[1])!r})\n"
        "from viz._rollouts import rollout\n"
        "from oasis_torchrl.viz import RolloutLogger\n"
        f"rerun_logger = RolloutLogger({str(out)!r})\n"
        "rerun_logger.log_rollout(rollout(1, 2))\n"
    )
    command = [sys.executable, "-c", script]
    run = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "Exception ignored" not in run.stderr
    assert Readback(out).images("env/0/camera/front")[0] == [3, 7, 11]


@pytest.mark.skipif(RrdReader is None, reason="reads chunks with rerun-sdk 0.32 or newer")
def test_a_file_gets_few_large_chunks(tmp_path: Path) -> None:
    """Steps logged slower than rerun's default batching (200 ms) and a live viewer's series (1 s)
    still share chunks: each chunk carries its schema, which would otherwise outweigh a frame."""
    import time

    td = rollout(1, 5)
    with RolloutLogger(tmp_path / "slow.rrd", LogOptions(background=False)) as rerun_logger:
        for t in range(5):
            rerun_logger.log_rollout(td[:, t : t + 1], new_episodes=t == 0)
            time.sleep(0.3)
    chunks = [chunk.entity_path for chunk in RrdReader(tmp_path / "slow.rrd").stream()]
    assert chunks.count("/env/0/camera/front") == 1  # the batcher's chunks
    assert chunks.count("/env/0/action/throttle") == 2  # its style (static), its values
    assert Readback(tmp_path / "slow.rrd").images("env/0/camera/front")[0] == [3, 7, 11, 15, 19, 23]
