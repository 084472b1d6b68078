"""Fixtures of the training tests: tiny env settings and a tiny autopilot dataset."""

from __future__ import annotations

from pathlib import Path

import pytest

from oasis_torchrl.data import LeRobotRecorder
from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig

TINY_ENV = [
    "env.image_size=[32,48]",
    "env.server.width=48",
    "env.server.height=32",
]
"""Overrides that make any train config's env tiny (32x48 policy images, 48x32 frames)."""


def tiny_ppo(output: Path, total_frames: int, *extra: str) -> list[str]:
    """Overrides of a PPO run on the tiny env: 2 rows of 6 chunks, batches of 16 env steps,
    minibatches of 8, a final evaluation of one 2-chunk episode, no progress bars."""
    return [
        *TINY_ENV,
        "env.num_envs=2",
        "env.max_steps=6",
        f"output_dir={output}",
        "collector.frames_per_batch=16",
        f"collector.total_frames={total_frames}",
        "optim.mini_batch_size=8",
        "eval.episodes=1",
        "eval.max_steps=2",
        "progress=false",
        *extra,
    ]


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two 4-step autopilot episodes, frame rows (16 rows each) at 32x48, with the privileged
    state."""
    root = tmp_path_factory.mktemp("bc") / "drives"
    env = OasisEnv(
        "local",
        num_envs=2,
        prompts="urban",
        server=ServerConfig(width=48, height=32),
        all_frames=True,
        max_steps=4,
        expert=True,
    )
    try:
        with LeRobotRecorder(root, privileged=True) as recorder:
            recorder.write(env.rollout(4, Autopilot(), break_when_any_done=False))
    finally:
        env.close()
    return root
