"""``lerobot-train`` and ``lerobot-eval`` with ``--env.type=oasis``: the project's policy and a
stock ACT trained on the project's own dataset, evaluated in the world model by LeRobot and by
``oasis-torchrl eval`` with the same numbers."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ._cli import cli_env, run_tool
from ._policies import oasis_folder

TIMEOUT_S = 900.0
SEED = 1000
SESSIONS = 3
CHUNKS = 12


@pytest.fixture(scope="module")
def home(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("hf")


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory, home: Path) -> Path:
    """The project's own dataset: autopilot drives, one row per frame, 64x96."""
    root = tmp_path_factory.mktemp("data") / "drives"
    args = ["record", "--root", str(root), "--episodes", "2", "--num-envs", "2"]
    args += ["--max-steps", "6", "--width", "96", "--height", "64"]
    run_tool("oasis-torchrl", args, cli_env(home), TIMEOUT_S)
    return root


def _train(drives: Path, output: Path, home: Path, *policy: str) -> Path:
    args = [
        *policy,
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--dataset.repo_id=local/drives",
        f"--dataset.root={drives}",
        "--steps=2",
        "--batch_size=2",
        "--num_workers=0",
        "--save_freq=2",
        f"--output_dir={output}",
    ]
    run_tool("lerobot-train", args, cli_env(home), TIMEOUT_S)
    return output / "checkpoints" / "last" / "pretrained_model"


@pytest.fixture(scope="module")
def act(tmp_path_factory: pytest.TempPathFactory, drives: Path, home: Path) -> Path:
    """A stock ACT trained by ``lerobot-train`` on the project's dataset (tiny, no downloads)."""
    return _train(
        drives,
        tmp_path_factory.mktemp("act") / "run",
        home,
        "--policy.type=act",
        "--policy.pretrained_backbone_weights=null",
        "--policy.dim_model=32",
        "--policy.n_heads=2",
        "--policy.dim_feedforward=64",
        "--policy.n_encoder_layers=1",
        "--policy.use_vae=false",
        "--policy.chunk_size=8",
        "--policy.n_action_steps=8",
        "--env_eval_freq=0",
    )


@pytest.fixture(scope="module")
def oasis_run(tmp_path_factory: pytest.TempPathFactory, drives: Path, home: Path) -> Path:
    """The project's policy trained by ``lerobot-train``, evaluated in the world model at its
    last step (``--env.type=oasis --env_eval_freq``)."""
    output = tmp_path_factory.mktemp("oasis") / "run"
    _train(
        drives,
        output,
        home,
        "--policy.type=oasis",
        "--env.type=oasis",
        "--env.episode_length=8",
        "--env_eval_freq=2",
        "--eval.n_episodes=2",
        "--eval.batch_size=2",
    )
    return output


def _lerobot_eval(policy: Path, output: Path, home: Path, sessions: int, chunks: int) -> dict:
    args = [
        f"--policy.path={policy}",
        "--env.type=oasis",
        "--env.task=urban",
        f"--env.episode_length={4 * chunks}",
        f"--eval.batch_size={sessions}",
        f"--eval.n_episodes={sessions}",
        f"--seed={SEED}",
        f"--output_dir={output}",
    ]
    done = run_tool("lerobot-eval", args, cli_env(home), TIMEOUT_S)
    info = json.loads((output / "eval_info.json").read_text())
    return {"info": info, "log": done.stdout + done.stderr}


@pytest.mark.timeout(1800)
def test_lerobot_train_evaluates_in_the_world_model(oasis_run: Path) -> None:
    videos = sorted((oasis_run / "eval").glob("videos_step_*/oasis_0/eval_episode_*.mp4"))
    assert len(videos) == 2 and all(video.stat().st_size > 0 for video in videos)


@pytest.mark.timeout(1800)
def test_lerobot_eval_runs_the_projects_policy(oasis_run: Path, tmp_path: Path, home: Path) -> None:
    policy = oasis_run / "checkpoints" / "last" / "pretrained_model"
    result = _lerobot_eval(policy, tmp_path / "eval", home, sessions=2, chunks=3)
    overall = result["info"]["overall"]
    assert overall["n_episodes"] == 2 and len(overall["video_paths"]) == 2
    assert overall["avg_sum_reward"] >= 0.0 and 0.0 <= overall["pc_success"] <= 100.0


def _both_evals_agree(
    policy: Path, tmp_path: Path, home: Path, tolerance: float = 1e-6
) -> list[float]:
    """Evaluate ``policy`` with lerobot-eval and with oasis-torchrl eval on the same seeds:
    the same distance and success per episode; returns the distances."""
    lerobot = _lerobot_eval(policy, tmp_path / "lerobot", home, sessions=SESSIONS, chunks=CHUNKS)
    assert f"pool of {SESSIONS} sessions" in lerobot["log"]  # one pool: N sessions at once
    metrics = lerobot["info"]["per_task"][0]["metrics"]
    assert len(metrics["video_paths"]) == SESSIONS

    output = tmp_path / "oasis.json"
    args = ["eval", f"policy={policy}", f"episodes={SESSIONS}", f"seeds=[{SEED}]"]
    args += [f"max_steps={CHUNKS}", f"output={output}"]
    run_tool("oasis-torchrl", args, cli_env(home), TIMEOUT_S)
    report = json.loads(output.read_text())["per_episode"]
    distances = [e["distance"] for e in report]
    assert metrics["sum_rewards"] == pytest.approx(distances, rel=tolerance)
    assert metrics["successes"] == [not e["collided"] for e in report]
    return metrics["sum_rewards"]


@pytest.mark.timeout(1800)
def test_a_stock_act_gets_the_same_metrics_from_lerobot_eval_and_oasis_torchrl_eval(
    act: Path, tmp_path: Path, home: Path
) -> None:
    _both_evals_agree(act, tmp_path, home)


@pytest.mark.timeout(1800)
def test_the_projects_two_frame_policy_gets_the_same_metrics_from_both_evals(
    tmp_path: Path, home: Path
) -> None:
    """lerobot-eval feeds the policy one frame per tick (a new one every 4 ticks) and the
    policy keeps its own history; oasis-torchrl eval gives it the env's frame stack. Both must
    show it the same two frames, one chunk apart. (LeRobot hands the network float frames,
    TorchRL uint8 ones: their float32 rounding differs in the last bits, hence a tolerance far
    below what different frames give.)"""
    policy = oasis_folder(tmp_path / "oasis")
    distances = _both_evals_agree(policy, tmp_path, home, tolerance=1e-3)
    assert min(distances) > 0.1 and len(set(distances)) > 1  # it drives, each world its own way
