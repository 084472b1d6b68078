"""Settings shared by the Ray tests."""

from __future__ import annotations

from pathlib import Path


def smoke_ppo(output_dir: Path) -> list[str]:
    """PPO at smoke size on Ray: 48x32 frames, two batches of 16 env steps from 2 collectors of
    2 sessions each, one epoch, no evaluation."""
    return [
        "env.image_size=[32,48]",
        "env.server.width=48",
        "env.server.height=32",
        "env.max_steps=6",
        f"output_dir={output_dir}",
        "collector.frames_per_batch=16",
        "collector.total_frames=32",
        "optim.mini_batch_size=8",
        "optim.epochs=1",
        "eval.every=0",
        "eval.episodes=0",
        "progress=false",
        "ray.enabled=true",
        "ray.num_collectors=2",
        "ray.sessions_per_env=2",
    ]
