"""Shipped policies end to end, tiny: a smoke PPO run's policy shipped with its card into a
temporary folder of shipped policies (``OASIS_PRETRAINED_POLICIES``), then loaded as
``pretrained:NAME`` by eval, record, the pipeline's comparison and ``pretrained path``; unknown
names and incomplete runs are one-line errors."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from omegaconf import OmegaConf
from viz._readback import Readback

from oasis_torchrl.cli import main
from oasis_torchrl.config import load_config, save_config
from oasis_torchrl.config.scenes import HELD_OUT_SCENES
from oasis_torchrl.drivers import PolicyDriver, load_driver
from oasis_torchrl.drivers.pretrained import POLICIES_ENV_VAR
from oasis_torchrl.envs import capabilities
from oasis_torchrl.models.checkpoint import BEST, LATEST, load_checkpoint
from oasis_torchrl.train import pipeline, plan, stages
from oasis_torchrl.train.cards import TrainingRun, card_text, matching_preset

from .conftest import TINY_ENV, tiny_ppo

TINY_CARD = [
    *TINY_ENV,
    "episodes=1",
    "max_steps=2",
    "held_out_seeds=[4241]",
    "commit=abc123",
    "progress=false",
]
"""Overrides of ``pretrained ship`` on the tiny env: one 2-chunk episode per prompt and seed."""


@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A smoke PPO run (16 env steps, evaluated every iteration) of a policy that reads the
    front crop, as the shipped ones do: its folder."""
    run = tmp_path_factory.mktemp("run") / "ppo"
    crop = "env.front_crop=0.5"
    overrides = tiny_ppo(run, 16, "eval.every=1", "checkpoint.keep_evaluated=true", crop)
    assert main(["train", "ppo", *overrides]) == 0
    return run


@pytest.fixture(scope="module")
def shipped(ppo_run: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of shipped policies holding the smoke run's policy as ``tiny``."""
    folder = tmp_path_factory.mktemp("policies")
    command = ["pretrained", "ship", str(ppo_run / "policy"), "tiny", f"output={folder}"]
    assert main([*command, *TINY_CARD]) == 0
    return folder


@pytest.fixture
def registry(shipped: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv(POLICIES_ENV_VAR, str(shipped))
    return shipped


def test_the_card_holds_the_command_commit_figures_and_curve(shipped: Path, ppo_run: Path) -> None:
    folder = shipped / "tiny"
    assert {"config.json", "model.safetensors", "README.md", "curve.png", "card.json"} <= {
        path.name for path in folder.iterdir()
    }
    assert not list(shipped.glob(".*partial"))
    card = json.loads((folder / "card.json").read_text())
    assert card["kind"] == "ppo" and card["commit"] == "abc123"
    assert card["command"].startswith("oasis-torchrl train ppo --config ")
    assert card["wall_seconds"] > 0 and "cores" in card["machine"]
    assert card["budget"] == "16 env steps"
    scenes = [row["scene"] for row in card["figures"]]
    assert scenes == ["urban", *HELD_OUT_SCENES]  # the report, then each held-out scene
    assert all(row["episodes"] == 1 and row["baseline_distance"] > 0 for row in card["figures"])
    readme = (folder / "README.md").read_text()
    assert "# pretrained:tiny" in readme and card["command"] in readme
    assert "held out: highway at night in the rain | 4241 | 1 |" in readme
    assert "![training curve](curve.png)" in readme and (folder / "curve.png").stat().st_size
    assert "ground truth" in readme  # distances need the embedded server, said plainly
    settings = readme.split("## Settings", 1)[1]  # the recipe, not where it ran
    assert "output_dir: <run>" in settings and str(ppo_run) not in settings
    # the crop is named, and every command the card gives turns it on
    assert card["front_crop"] == 0.5 and "--env.front_crop=0.5 --eval" in readme


def test_a_card_names_the_earlier_policy_its_run_kept(
    ppo_run: Path, shipped: Path, tmp_path: Path
) -> None:
    """A run whose selection evaluations (seed 2000) kept the policy of 8 env steps
    (``best.pt``) ships that one: the card says so, and its curve draws the final evaluation
    (seed 1000, of that policy) apart; a run that kept its last policy says nothing of it."""
    run = tmp_path / "ppo"
    shutil.copytree(ppo_run, run)
    latest = load_checkpoint(run / "checkpoints" / LATEST)
    evaluations = [(16, [2000], 20.0), (8, [2000], 30.0), (8, [1000], 25.0)]
    history = [
        {"policy_frames": x, "seeds": seeds, "mean_distance": y} for x, seeds, y in evaluations
    ]
    torch.save({**latest, "history": history}, run / "checkpoints" / LATEST)
    facts = json.loads((shipped / "tiny" / "card.json").read_text())
    for frames, kept in ((8, 8), (16, None)):
        torch.save({**latest, "frames": frames}, run / "checkpoints" / BEST)
        training = TrainingRun.of(run / "policy")
        assert training.kept_steps == kept
        text = card_text({**facts, "kept_steps": kept}, "")
        assert ("It is the policy of 8 env steps" in text) is (kept is not None)
    assert training.curve == {
        "evaluations on seed 2000": [(8, 30.0), (16, 20.0)],
        "evaluations on seed 1000": [(8, 25.0)],
    }


def test_shipping_again_or_from_an_incomplete_run_is_a_one_line_error(
    ppo_run: Path, shipped: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    again = ["pretrained", "ship", str(ppo_run / "policy"), "tiny", f"output={shipped}"]
    assert main([*again, *TINY_CARD]) == 2
    incomplete = tmp_path / "ppo"
    shutil.copytree(ppo_run, incomplete, ignore=shutil.ignore_patterns("checkpoints"))
    command = ["pretrained", "ship", str(incomplete / "policy"), "other", f"output={tmp_path}"]
    with caplog.at_level(logging.ERROR):
        assert main([*command, *TINY_CARD]) == 2
    errors = [record.getMessage() for record in caplog.records if record.levelno == logging.ERROR]
    assert "delete it" in errors[0]
    assert errors[1].endswith(
        f"the run lacks {incomplete}/checkpoints/latest.pt, which the card needs"
    )
    assert not (tmp_path / "other").exists()


def test_a_shipped_policy_loads_by_name_in_eval_record_and_path(
    registry: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert isinstance(load_driver("pretrained:tiny"), PolicyDriver)
    assert main(["pretrained", "list"]) == 0
    assert capsys.readouterr().out == "tiny\n"
    assert main(["pretrained", "path", "tiny"]) == 0
    assert capsys.readouterr().out == f"{registry / 'tiny'}\n"
    evaluate = ["eval", "policy=pretrained:tiny", "episodes=1", "max_steps=2", *TINY_ENV]
    assert main([*evaluate, "prompts=[urban,highway]"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["policy"] == "pretrained:tiny"
    assert set(report["per_prompt"]) == {"urban", "highway"}  # each scene on its own
    root = tmp_path / "drives"
    record = ["record", f"root={root}", "driver=policy", "policy=pretrained:tiny", "episodes=1"]
    assert main([*record, "env.num_envs=1", "env.max_steps=2", *TINY_ENV]) == 0
    assert LeRobotDataset("local/drives", root=root, video_backend="pyav").num_episodes == 1


def test_unknown_names_are_one_line_errors_listing_the_shipped(
    registry: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with pytest.raises(ValueError, match=r"^no shipped policy named 'nope' \(shipped: tiny\)$"):
        load_driver("pretrained:nope")
    with caplog.at_level(logging.ERROR):
        assert main(["pretrained", "path", "nope"]) == 2
        assert main(["eval", "policy=pretrained:nope"]) == 2
        assert main(["serve-policy", "pretrained:nope", "--api-key", "k"]) == 2
        # the main job fails before its first stage
        assert main(["demo", f"output_dir={tmp_path / 'demo'}", "eval.pretrained=[nope]"]) == 2
    assert not (tmp_path / "demo").exists()
    errors = [record.getMessage() for record in caplog.records if record.levelno == logging.ERROR]
    assert len(errors) == 4 and all("no shipped policy named 'nope'" in e for e in errors)
    assert all("\n" not in error for error in errors)


def test_the_main_job_lists_shipped_policies_and_a_fine_tune_not_kept(
    registry: Path, ppo_run: Path
) -> None:
    assert plan.shipped_specs(None) == {"pretrained:tiny": "pretrained:tiny"}
    cfg = load_config("demo", [*TINY_ENV, "eval.episodes=1", "eval.max_steps=2", "progress=false"])
    policies = {
        "constant:throttle=1.0": "constant:throttle=1.0",
        "pretrained:tiny": "pretrained:tiny",
    }
    policies["bc"] = str(ppo_run / "policy")
    evaluations = stages.evaluate_all(plan.EvaluationPlan.of(cfg), policies, record=True)
    cards = {"pretrained:tiny": json.loads((registry / "tiny" / "card.json").read_text())}
    paths = [Path()] * 7
    seconds = {"bc": 60.0, pipeline.EVALUATION: 300.0}
    result = pipeline.PipelineResult(*paths, evaluations, seconds, False, cards)
    rows = result.rows()
    assert [(row.name, row.kind) for row in rows] == [
        ("constant:throttle=1.0", "constant"),
        ("pretrained:tiny", "shipped"),
        ("bc", "learned"),
        ("bc+ppo", "not kept"),
    ]
    table = result.table().splitlines()
    assert table[4].split() == ["bc+ppo", "not", "kept"]  # not the clone's row again
    assert table[5].startswith("This run learned in 1 min: bc drives ")  # not the evaluation
    assert "pretrained:tiny 16 env steps, 0.0 h on " in table[5]
    assert table[7].startswith("6.0 min (bc 60 s, eval 300 s); summary ")
    assert result.to_dict()["fine_tune_kept"] is False


def test_only_the_best_learned_policy_is_recorded_beside_the_compared_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The best ("fast", not last) is recorded beside the autopilot; no other episode is
    recorded, and the compared autopilot drives once, in the recorded pass."""
    recorded: list[bool] = []
    for_driver = stages.Evaluator.for_driver

    def counting_for_driver(env_cfg, eval_cfg, driver, **kwargs):
        recorded.append(bool(eval_cfg.rerun or kwargs.get("rerun_logger")))
        return for_driver(env_cfg, eval_cfg, driver, **kwargs)

    monkeypatch.setattr(stages.Evaluator, "for_driver", counting_for_driver)
    rerun = tmp_path / "eval.rrd"
    overrides = [*TINY_ENV, "eval.episodes=1", "eval.max_steps=2", "progress=false"]
    cfg = load_config("demo", [*overrides, f"eval.rerun={rerun}", "eval.compare=[autopilot]"])
    policies = {
        "autopilot": "autopilot",
        "fast": "constant:throttle=1.0",
        "slow": "constant:throttle=0.2",
    }
    results = stages.evaluate_and_record_best(plan.EvaluationPlan.of(cfg), policies, [])
    assert list(results) == list(policies)  # the table keeps the policies' order
    assert results["fast"]["mean_distance"] > results["slow"]["mean_distance"]
    assert recorded == [False, False, True, True]  # fast, slow; then autopilot, fast
    entities = " ".join(Readback(rerun).entities())
    assert "fast" in entities and "autopilot" in entities and "slow" not in entities


def test_a_shipped_policy_drives_the_hosted_like_server_and_its_card_needs_ground_truth(
    registry: Path,
    ppo_run: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
    caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(capabilities, "_probed", {})  # probed once a process: forget earlier tests
    hosted = [*TINY_ENV, "env.server.hosted=true"]
    evaluate = ["eval", "policy=pretrained:tiny", "episodes=1", "max_steps=2", *hosted]
    assert main(evaluate) == 0  # a camera policy: frames are all it reads
    assert json.loads(capsys.readouterr().out)["ground_truth"] is False
    command = ["pretrained", "ship", str(ppo_run / "policy"), "hosted", f"output={tmp_path}"]
    with caplog.at_level(logging.ERROR):
        assert main([*command, *TINY_CARD, "env.server.hosted=true"]) == 2
    assert "need the embedded server's ground truth" in caplog.text
    assert not (tmp_path / "hosted").exists()


@pytest.mark.parametrize(
    ("command", "preset"), [("ppo", "pretrained_ppo_scratch"), ("demo", "pretrained_clone")]
)
def test_a_run_of_a_preset_names_the_preset_on_its_card(
    command: str, preset: str, tmp_path: Path
) -> None:
    run = load_config(command, ["output_dir=elsewhere", "progress=false"], file=preset)
    saved = OmegaConf.load(save_config(run, tmp_path / "config.yaml"))  # as the card reads it
    assert matching_preset(command, saved) == preset
    changed = load_config(command, ["seed=7"], file=preset)
    assert matching_preset(command, changed) is None  # the card then names the saved settings
