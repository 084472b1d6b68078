"""Every command with its defaults against the hosted-like server (frames only), and nothing
privileged (truth, expert, depth) in what they make."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import pytest

from oasis_torchrl.cli import main
from oasis_torchrl.envs import OasisEnv, capabilities
from oasis_torchrl.sim.config import ServerConfig

from .conftest import TINY_ENV, tiny_ppo

HOSTED = ["env.server.hosted=true"]
PRIVILEGED_WORDS = ("truth", "expert", "depth", "critic_inputs", "privileged")
PRIVILEGED_KEYS_IN_LOGS = ("'truth'", "expert_action", "critic_inputs", "('depth'")


def _privileged(names: object) -> list[str]:
    return [str(name) for name in names if any(w in str(name) for w in PRIVILEGED_WORDS)]


def test_hosted_like_env_sends_frames_and_scores_them_with_the_motion_reward() -> None:
    env = OasisEnv("local", 2, server=ServerConfig(width=96, height=64, hosted=True), max_steps=3)
    try:
        rollout = env.rollout(3, break_when_any_done=False)
    finally:
        env.close()
    keys = rollout.keys(include_nested=True, leaves_only=True)
    assert not _privileged(keys)
    assert ("next", "reward_terms", "seen_progress") in keys  # the frames-only motion reward
    # The env observes the last frame of each chunk; the reward read all four.
    assert rollout["next", "pixels", "front"].shape == (2, 3, 64, 96, 3)


def test_train_eval_record_defaults_run_on_frames_alone(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(capabilities, "_probed", {})  # probed once a process: forget earlier tests
    caplog.set_level(logging.INFO)
    assert main(["train", "ppo", *tiny_ppo(tmp_path / "ppo", 16, *HOSTED)]) == 0
    assert caplog.text.count("sends frames only") == 1

    report_path = tmp_path / "eval.json"
    rerun_path = tmp_path / "eval.rrd"
    evaluated = [f"policy={tmp_path / 'ppo' / 'policy'}", "episodes=2", "max_steps=3"]
    outputs = [f"output={report_path}", f"rerun={rerun_path}"]
    assert main(["eval", *evaluated, *outputs, *TINY_ENV, *HOSTED]) == 0
    report = json.loads(report_path.read_text())
    assert report["ground_truth"] is False and "ignores seeds" in report["note"]
    # Metres seen, signed: an untrained policy may back up (scenes are random, seeds ignored)
    assert 1 <= report["mean_steps"] <= 3 and math.isfinite(report["mean_progress"])

    root = tmp_path / "recorded"
    sizes = ["env.server.width=96", "env.server.height=64", "env.num_envs=1", "env.max_steps=2"]
    assert main(["record", "--root", str(root), "episodes=1", *sizes, *HOSTED]) == 0
    features = json.loads((root / "meta" / "info.json").read_text())["features"]
    assert "observation.images.front" in features
    assert not _privileged(features)
    assert not [key for key in PRIVILEGED_KEYS_IN_LOGS if key in caplog.text]
    assert rerun_path.stat().st_size > 0


def test_demo_on_frames_alone_stops_at_once_without_a_source(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    assert main(["demo", f"output_dir={tmp_path}", *HOSTED]) == 2
    assert "pass record.source=" in caplog.text
    assert not (tmp_path / "demos").exists()


def test_demo_runs_the_whole_loop_on_frames_alone(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from viz._readback import Readback

    from .test_pipeline import TINY_PIPELINE

    demonstrator = "record.source=constant:throttle=0.6,steering=0.0"
    lighter = ["eval.reference=[autopilot]", "ppo.eval.episodes=1", "ppo.eval.selection_margin=0"]
    settings = [*TINY_PIPELINE, *HOSTED, demonstrator, *lighter]
    assert main(["demo", f"output_dir={tmp_path}", *settings]) == 0
    table = capsys.readouterr().out.splitlines()
    summary = json.loads((tmp_path / "summary.json").read_text())
    # no autopilot on frames alone; a fine-tune that was not kept has no evaluation of its own
    learned = ["bc", "bc+ppo"] if summary["fine_tune_kept"] else ["bc"]
    assert list(summary["evaluations"]) == learned
    dataset = json.loads(
        (tmp_path / "bc" / "round_1" / "dataset" / "meta" / "info.json").read_text()
    )
    assert dataset["total_episodes"] == 4  # 2 demonstrations + 2 DAgger episodes
    assert all(not report["ground_truth"] for report in summary["evaluations"].values())
    assert "mean return (frames only)" in table[0]
    assert not _privileged(dataset["features"])
    recording = Readback(tmp_path / "eval.rrd")
    assert not _privileged(recording.entities())


def test_evaluation_scores_the_reference_reward_beside_ground_truth() -> None:
    from oasis_torchrl.config import load_config
    from oasis_torchrl.drivers import ScriptedDriver
    from oasis_torchrl.evaluation import Evaluator

    cfg = load_config("eval", [*TINY_ENV, "episodes=2", "max_steps=3"])
    with Evaluator(cfg.env, cfg, progress=False) as evaluator:
        report = evaluator.evaluate(ScriptedDriver.from_spec("throttle=1"))
    summary = report.to_dict()
    assert summary["ground_truth"] is True and summary["mean_distance"] > 0
    assert summary["mean_progress"] > 0 and "mean_reference_return" in summary
    assert all(episode["reference_return"] is not None for episode in summary["per_episode"])
