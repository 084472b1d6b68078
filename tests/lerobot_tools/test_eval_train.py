"""``lerobot-train`` and ``lerobot-eval`` with ``--env.type=oasis``: the project's policy and a
stock ACT trained on the project's own dataset, evaluated in the world model by LeRobot and by
``oasis-torchrl eval`` with the same numbers.

Each ``lerobot-train`` runs once per module (a fixture) and every test that only reads its output
shares it; ``oasis-torchrl record`` and ``eval`` run in-process (their console script runs in
``tests/docs``), LeRobot's tools as their own console scripts."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest
from lerobot_policy_oasis import OasisPolicy

from oasis_torchrl.cli import main

from ._cli import cli_env, run_tool
from ._policies import oasis_folder

TIMEOUT_S = 900.0
SEED = 1000
SESSIONS = 3
CHUNKS = 12
POLICY_IMAGE_SIZE = (32, 48)
"""The project's policy sees the 64x96 frames resized (its processor does it)."""


@dataclass(frozen=True)
class TrainRun:
    """What one ``lerobot-train`` left: its output folder and what it printed."""

    output: Path
    log: str

    @property
    def policy(self) -> Path:
        return self.output / "checkpoints" / "last" / "pretrained_model"


@pytest.fixture(scope="module")
def home(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("hf")


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The project's own dataset: autopilot drives, one row per frame, 64x96."""
    root = tmp_path_factory.mktemp("data") / "drives"
    args = ["record", "--root", str(root), "--episodes", "2", "--num-envs", "2"]
    assert main([*args, "--max-steps", "6", "--width", "96", "--height", "64"]) == 0
    return root


def _train(drives: Path, output: Path, home: Path, *policy: str) -> TrainRun:
    args = [
        *policy,
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--dataset.repo_id=local/drives",
        f"--dataset.root={drives}",
        "--steps=2",
        "--batch_size=2",
        "--num_workers=0",
        "--log_freq=1",
        "--save_freq=2",
        f"--output_dir={output}",
    ]
    done = run_tool("lerobot-train", args, cli_env(home), TIMEOUT_S)
    return TrainRun(output, done.stdout + done.stderr)


@pytest.fixture(scope="module")
def act(tmp_path_factory: pytest.TempPathFactory, drives: Path, home: Path) -> TrainRun:
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
        "--policy.n_decoder_layers=1",
        "--policy.use_vae=false",
        "--policy.chunk_size=8",
        "--policy.n_action_steps=8",
        "--env_eval_freq=0",
    )


@pytest.fixture(scope="module")
def oasis_run(tmp_path_factory: pytest.TempPathFactory, drives: Path, home: Path) -> TrainRun:
    """The project's policy trained by ``lerobot-train`` (a network field and the image size
    set by flag), evaluated in the world model at its last step (``--env.type=oasis
    --env_eval_freq``)."""
    size = ",".join(map(str, POLICY_IMAGE_SIZE))
    return _train(
        drives,
        tmp_path_factory.mktemp("oasis") / "run",
        home,
        "--policy.type=oasis",
        f"--policy.image_size=[{size}]",
        "--policy.components=2",  # a network field, taken from DrivingNetConfig
        "--env.type=oasis",
        "--env.episode_length=8",
        "--env_eval_freq=2",
        "--eval.n_episodes=2",
        "--eval.batch_size=2",
    )


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
def test_lerobot_train_trains_a_stock_act_on_the_projects_dataset(act: TrainRun) -> None:
    assert "step:2 " in act.log and "End of training" in act.log
    assert (act.policy / "model.safetensors").exists()


@pytest.mark.timeout(1800)
def test_lerobot_train_evaluates_in_the_world_model(oasis_run: TrainRun) -> None:
    videos = sorted((oasis_run.output / "eval").glob("videos_step_*/oasis_0/eval_episode_*.mp4"))
    assert len(videos) == 2 and all(video.stat().st_size > 0 for video in videos)


def _policy_settings(config) -> dict[str, object]:
    """What a trained policy's config says about the policy (not where it ran)."""
    from lerobot_policy_oasis.configuration_oasis import NETWORK_FIELDS, TRAINING_FIELDS

    names = (*NETWORK_FIELDS, *TRAINING_FIELDS, "n_obs_steps", "chunk_size", "n_action_steps")
    settings = {name: getattr(config, name) for name in names}
    settings["features"] = (config.input_features, config.output_features)
    settings["normalization"] = config.normalization_mapping
    return settings


@pytest.mark.timeout(1800)
def test_lerobot_train_and_train_bc_build_the_same_policy(
    oasis_run: TrainRun, drives: Path, tmp_path: Path
) -> None:
    loaded = OasisPolicy.from_pretrained(oasis_run.policy)
    assert loaded.config.image_size == POLICY_IMAGE_SIZE and loaded.model.config.components == 2
    assert (oasis_run.policy / "policy_preprocessor.json").exists()

    size = ",".join(map(str, POLICY_IMAGE_SIZE))
    bc = ["train", "bc", f"--dataset.root={drives}", f"output_dir={tmp_path / 'bc'}"]
    bc += [f"policy.image_size=[{size}]", "policy.components=2", "train.steps=2"]
    assert main([*bc, "eval.episodes=0", "train.batch_size=2", "progress=false"]) == 0
    cloned = OasisPolicy.from_pretrained(tmp_path / "bc" / "policy").config
    assert _policy_settings(cloned) == _policy_settings(loaded.config)


@pytest.mark.timeout(1800)
def test_lerobot_eval_runs_the_projects_policy(
    oasis_run: TrainRun, tmp_path: Path, home: Path
) -> None:
    result = _lerobot_eval(oasis_run.policy, tmp_path / "eval", home, sessions=2, chunks=3)
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
    assert main([*args, f"max_steps={CHUNKS}", f"output={output}"]) == 0
    report = json.loads(output.read_text())["per_episode"]
    distances = [e["distance"] for e in report]
    assert metrics["sum_rewards"] == pytest.approx(distances, rel=tolerance)
    assert metrics["successes"] == [not e["collided"] for e in report]
    return metrics["sum_rewards"]


@pytest.mark.timeout(1800)
def test_a_stock_act_gets_the_same_metrics_from_lerobot_eval_and_oasis_torchrl_eval(
    act: TrainRun, tmp_path: Path, home: Path
) -> None:
    _both_evals_agree(act.policy, tmp_path, home)


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
