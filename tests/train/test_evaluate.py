"""Evaluation: metrics from rollouts, determinism, the eval command."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.cli import main
from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import ScriptedDriver
from oasis_torchrl.train.evaluate import Evaluator, episode_results

from .conftest import TINY_ENV


def test_episode_results_stop_at_the_first_done() -> None:
    done = torch.tensor([[False, True, True], [False, False, False]]).unsqueeze(-1)
    distance = torch.tensor([[1.0, 2.0, 2.0], [1.0, 2.0, 3.0]]).unsqueeze(-1).expand(2, 3, 4)
    rollout = TensorDict(
        {
            "prompt": "urban",
            "episode_seed": torch.tensor([[7], [8]]).unsqueeze(1).expand(2, 3, 1),
            "next": {
                "done": done,
                "terminated": done,
                "reward": torch.tensor([[1.0, -10.0, 5.0], [1.0, 1.0, 1.0]]).unsqueeze(-1),
                "truth": {"distance": distance, "collided": done.float().expand(2, 3, 4)},
            },
        },
        batch_size=[2, 3],
    )
    first, second = episode_results(rollout)
    assert (first.distance, first.collided, first.episode_return, first.steps) == (
        2.0,
        True,
        -9.0,
        2,
    )
    assert (second.distance, second.collided, second.episode_return, second.steps) == (
        3.0,
        False,
        3.0,
        3,
    )
    assert (first.episode_seed, first.prompt) == (7, "urban")


def test_evaluation_is_repeatable(tmp_path: Path) -> None:
    cfg = load_config("eval", [*TINY_ENV, "episodes=2", "max_steps=4", "seeds=[3]"])
    with Evaluator(cfg.env, cfg, progress=False) as evaluator:
        first = evaluator.evaluate(ScriptedDriver.from_spec("throttle=1"))
        second = evaluator.evaluate(ScriptedDriver.from_spec("throttle=1"))
        other_seed = evaluator.evaluate(ScriptedDriver.from_spec("throttle=1"), seeds=[4])
        with pytest.raises(ValueError, match="at least one seed"):
            evaluator.evaluate(ScriptedDriver.from_spec("throttle=1"), seeds=[])
    assert first.to_dict() == second.to_dict()
    assert {e.episode_seed for e in other_seed.episodes}.isdisjoint(
        e.episode_seed for e in first.episodes
    )
    assert len(first.episodes) == 2 and first.mean_distance > 0
    assert first.episodes[0].episode_seed != first.episodes[1].episode_seed
    assert all(episode.steps == 4 for episode in first.episodes)
    path = first.write_json(tmp_path / "report.json", policy="constant")
    assert json.loads(path.read_text())["policy"] == "constant"


def test_eval_command_prints_the_report(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    output = tmp_path / "eval.json"
    code = main(
        [
            "eval",
            *TINY_ENV,
            "policy=constant:throttle=0.5",
            "episodes=1",
            "max_steps=2",
            f"output={output}",
        ]
    )
    assert code == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json.loads(output.read_text())
    assert set(printed) >= {"mean_distance", "collision_rate", "mean_return", "per_episode"}
    assert main(["eval", "policy=missing.pt"]) == 2
