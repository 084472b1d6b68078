"""The record -> BC (+ DAgger) -> PPO -> eval pipeline end to end, tiny."""

from __future__ import annotations

import json
from pathlib import Path

from oasis_torchrl.train.config import load_config
from oasis_torchrl.train.pipeline import run_pipeline

from .conftest import TINY_ENV


def test_pipeline_runs_every_stage(tmp_path: Path) -> None:
    cfg = load_config(
        "demo",
        [
            *TINY_ENV,
            f"output_dir={tmp_path}",
            "env.num_envs=2",
            "env.max_steps=3",
            "record.episodes=2",
            "bc.train.steps=3",
            "bc.train.batch_size=8",
            "dagger.rounds=1",
            "dagger.episodes=2",
            "dagger.steps=2",
            "ppo.collector.frames_per_batch=12",
            "ppo.collector.total_frames=12",
            "ppo.optim.mini_batch_size=6",
            "eval.episodes=1",
            "eval.max_steps=2",
            "eval.reference=[constant:throttle=1.0]",
            "progress=false",
        ],
    )
    result = run_pipeline(cfg)
    summary = json.loads(result.summary_path.read_text())
    assert list(summary["evaluations"]) == ["constant:throttle=1.0", "bc", "bc+ppo"]
    assert set(summary["seconds"]) == {"record", "bc", "ppo", "eval"}
    assert result.bc_policy == tmp_path / "bc" / "round_1" / "policy"
    info = json.loads((result.dataset / "meta" / "info.json").read_text())
    assert info["total_episodes"] == 4  # 2 demonstrations + 2 DAgger episodes
    assert (result.ppo_policy / "model.safetensors").exists()
