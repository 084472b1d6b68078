"""Rerun: log a live rollout (cameras, actions, rewards, ground truth, the top-down view), then
record a LeRobot dataset and replay it.

    python examples/rerun_rollouts.py          # writes .rrd files; open them with `rerun FILE`
    OASIS_EXAMPLE_SMOKE=1 python examples/rerun_rollouts.py   # a few steps (what the tests run)

Use ``"spawn"`` instead of a file name to open a viewer right away, or a
``rerun+http://host:9876/proxy`` URL to send to a viewer that is already running.
"""

from __future__ import annotations

import os
from pathlib import Path

from oasis_torchrl.data import LeRobotRecorder
from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.viz import LogOptions, RerunTransform, RolloutLogger
from oasis_torchrl.viz.lerobot_replay import DatasetReplay
from oasis_torchrl.viz.recording import open_recording

SMOKE = os.environ.get("OASIS_EXAMPLE_SMOKE") == "1"
STEPS = 4 if SMOKE else 100  # env steps (4 frames each)
SERVER = ServerConfig(width=96, height=64) if SMOKE else ServerConfig(width=384, height=256)
OUTPUT = Path("outputs/examples/rerun")


def log_live_rollout() -> Path:
    """Two rows driven by the server's autopilot, logged as they run (one tab per row)."""
    env = OasisEnv(
        "local",
        num_envs=2,
        prompts=["urban street", "rural road at sunset"],
        server=SERVER,
        expert=True,  # the autopilot drives with the server's expert
    )
    path = OUTPUT / "live.rrd"
    # The transform logs every reset and step and gives the logger the env's scene source,
    # so the top-down view shows the road, its lanes and the obstacles around the car.
    with RolloutLogger(path, LogOptions(rows=(0, 1))) as rerun_logger:
        logged = env.append_transform(RerunTransform(rerun_logger))
        logged.rollout(STEPS, Autopilot())
    env.close()
    return path


def record_and_replay_dataset() -> Path:
    """A small LeRobot dataset (one row per frame), replayed into an .rrd."""
    env = OasisEnv(
        "local",
        num_envs=2,
        prompts="highway",
        server=SERVER,
        all_frames=True,
        max_steps=STEPS,
        expert=True,
    )
    root = OUTPUT / "drives"
    with LeRobotRecorder(root, append=(root / "meta").exists()) as recorder:
        recorder.write(env.rollout(STEPS, Autopilot(), break_when_any_done=False))
    env.close()
    path = OUTPUT / "dataset.rrd"
    recording = open_recording(path)
    try:
        DatasetReplay(root, recording).log()  # every episode; .log([0, 3]) picks some
    finally:
        recording.flush()
        recording.disconnect()
    return path


if __name__ == "__main__":
    for path in (log_live_rollout(), record_and_replay_dataset()):
        print(f"wrote {path}: open it with `rerun {path}`")
