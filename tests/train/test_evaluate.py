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
from oasis_torchrl.evaluation import Evaluator, episode_results

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


def test_eval_command_compares_with_a_baseline(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    settings = [*TINY_ENV, "episodes=2", "max_steps=3", "seeds=[5]"]
    constant = tmp_path / "constant.json"
    assert main(["eval", *settings, "policy=constant:throttle=0.2", f"output={constant}"]) == 0
    assert "evaluating" in capsys.readouterr().err  # its progress bar
    faster = tmp_path / "faster.json"
    code = main(
        [
            "eval",
            *settings,
            "policy=constant:throttle=1.0",
            f"baseline={constant}",
            f"output={faster}",
            "progress=false",
        ]
    )
    assert code == 0
    report, before = json.loads(faster.read_text()), json.loads(constant.read_text())
    versus = report["vs_baseline"]
    assert versus["baseline"] == str(constant) and versus["episodes"] == 2.0
    assert versus["mean"] == pytest.approx(report["mean_distance"] - before["mean_distance"])
    assert versus["mean"] > 0
    printed = capsys.readouterr()
    assert json.loads(printed.out) == report and "evaluating" not in printed.err


def test_eval_command_keeps_the_report_when_the_baseline_ran_other_episodes(
    tmp_path: Path,
) -> None:
    baseline = tmp_path / "baseline.json"
    output = tmp_path / "eval.json"
    short = [*TINY_ENV, "episodes=2", "max_steps=2", "policy=constant:throttle=0.5"]
    assert main(["eval", *short, "seeds=[5]", f"output={baseline}"]) == 0
    code = main(["eval", *short, "seeds=[6]", f"baseline={baseline}", f"output={output}"])
    assert code == 2
    report = json.loads(output.read_text())
    assert "vs_baseline" not in report and len(report["per_episode"]) == 2


def test_eval_command_refuses_a_baseline_that_is_not_a_report(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"mean_distance": 3.0}))
    output = tmp_path / "eval.json"
    for baseline, problem in (
        (summary, "no per_episode"),
        (tmp_path / "gone.json", "no evaluation"),
    ):
        caplog.clear()
        assert main(["eval", *TINY_ENV, f"baseline={baseline}", f"output={output}"]) == 2
        assert problem in caplog.text
    assert not output.exists()
