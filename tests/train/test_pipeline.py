"""The main job (``oasis-torchrl demo``: record -> BC + DAgger -> PPO -> eval) end to end, tiny."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from viz._readback import Readback

from oasis_torchrl.cli import main
from oasis_torchrl.config import load_config
from oasis_torchrl.models.checkpoint import load_checkpoint
from oasis_torchrl.train import stages
from oasis_torchrl.train.cards import TrainingRun
from oasis_torchrl.train.plan import EvaluationPlan, plan_run
from oasis_torchrl.train.stage_seconds import STAGE_SECONDS, add_stage_seconds, timed_stage

from .conftest import TINY_ENV

TINY_PIPELINE = [
    *TINY_ENV,
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
    "ppo.eval.episodes=2",  # a paired standard error for the selection margin
    "ppo.eval.max_steps=2",
    "ppo.eval.every=1",
    "eval.episodes=1",
    "eval.max_steps=2",
    "eval.reference=[constant:throttle=1.0]",
    "eval.pretrained=[]",  # the shipped policies have their own tests
    "progress=false",
]


def episodes(root: Path) -> int:
    """The episodes of the LeRobot dataset at ``root``, read with lerobot."""
    return LeRobotDataset(f"local/{root.name}", root=root, video_backend="pyav").num_episodes


def fingerprint(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` by its path: a dataset left as it was has the same one."""
    return {
        str(path.relative_to(root)): path.read_bytes() for path in root.rglob("*") if path.is_file()
    }


def test_demo_command_runs_every_stage(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    threads: list[int] = []
    monkeypatch.setattr(torch, "set_num_threads", threads.append)  # the suite's own stays
    assert main(["demo", f"output_dir={tmp_path}", *TINY_PIPELINE]) == 0
    assert threads == [1]  # one torch thread: two fight over 2 cores with the server's processes
    printed = capsys.readouterr()
    table = printed.out.splitlines()
    assert "Map" not in printed.err  # no bar of `datasets` per saved episode, DAgger's included
    summary = json.loads((tmp_path / "summary.json").read_text())
    paths = {name: Path(path) for name, path in summary["paths"].items()}
    kept = load_checkpoint(paths["ppo_checkpoint"])
    fine_tuned = ["bc+ppo"] if kept["frames"] else []  # a fine-tuning not kept has no evaluation
    assert list(summary["evaluations"]) == ["constant:throttle=1.0", "bc", *fine_tuned]
    assert summary["fine_tune_kept"] == bool(kept["frames"])
    assert len(summary["evaluations"]["bc"]["per_episode"]) == 1
    assert set(summary["seconds"]) == {"record", "bc", "ppo", "eval"}
    assert table[0].startswith("policy") and table[0].endswith("vs best constant")
    assert [line.split()[0] for line in table[1:4]] == ["constant:throttle=1.0", "bc", "bc+ppo"]
    if not kept["frames"]:
        assert table[3].split() == ["bc+ppo", "not", "kept"]  # not the clone's row again
    assert table[1].endswith("1.00x")  # the constant is the best constant
    assert str(paths["plot"]) in table[-1] and paths["plot"].stat().st_size > 0
    assert paths["bc_policy"] == tmp_path / "bc" / "round_1" / "policy"
    assert episodes(paths["dataset"]) == 2  # the demonstrations; DAgger's are kept apart
    assert episodes(tmp_path / "bc" / "round_1" / "dagger") == 2
    assert episodes(tmp_path / "bc" / "round_1" / "dataset") == 4  # what round 1 cloned
    assert (paths["ppo_policy"] / "model.safetensors").exists()
    # the fine-tuned policy is kept only if it beats the clone on the selection seeds
    assert paths["ppo_checkpoint"].name == "best.pt" and kept["frames"] in (0, 12)
    latest = load_checkpoint(paths["ppo_checkpoint"].with_name("latest.pt"))
    assert latest["frames"] == 12
    # PPO evaluated on its selection seeds only: the eval stage is the final evaluation
    assert {tuple(entry["seeds"]) for entry in latest["history"]} == {(2000,)}
    assert paths["recording"] == tmp_path / "eval.rrd"
    recording = Readback(paths["recording"])
    assert any("front" in entity for entity in recording.entities())
    _, roads = recording.column("env/0/topdown/road", "LineStrips2D:strips")
    assert any(roads)  # the evaluator's env handed its scenes to the top-down view
    run = TrainingRun.of(paths["bc_policy"])  # what a card of the clone reads from the run
    assert (run.kind, run.root, run.budget) == (
        "demo",
        tmp_path,
        "2 demonstrations, 1 DAgger rounds",
    )
    totals = json.loads((tmp_path / STAGE_SECONDS).read_text())
    assert totals == {stage: summary["seconds"][stage] for stage in ("record", "bc", "ppo")}
    assert run.wall_seconds == totals["record"] + totals["bc"]
    assert list(run.curve) == ["round 0", "round 1"] and all(run.curve.values())
    assert run.curve["round 1"][0][0] > run.curve["round 0"][-1][0]  # one axis of steps
    assert run.command() == f"oasis-torchrl demo --config {tmp_path / 'config.yaml'}"


def test_a_stage_stopped_half_way_still_adds_its_time(tmp_path: Path) -> None:
    """A clone's wall time counts every run of its folder: the one a stop cut short too."""
    totals = tmp_path / STAGE_SECONDS
    add_stage_seconds(totals, "bc", 100.0)  # an earlier run's
    seconds: dict[str, float] = {}
    with pytest.raises(KeyboardInterrupt), timed_stage(seconds, "bc", totals):
        raise KeyboardInterrupt
    assert json.loads(totals.read_text()) == {"bc": 100.0 + seconds["bc"]}


def test_a_clone_stopped_in_a_rounds_cloning_resumes_it_without_recording_it_again(
    tiny_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The main job run again after a stop at DAgger round 1's third cloning step takes that
    round's steps 3 and 4 from its saved state; its episodes, recorded already, are not
    recorded twice."""
    from lerobot_policy_oasis import OasisPolicy

    from oasis_torchrl.train import bc

    dataset = tmp_path / "demos"
    shutil.copytree(tiny_dataset, dataset)
    overrides = [*TINY_PIPELINE, "dagger.steps=4", "bc.train.save_every=2"]
    rounds = plan_run(load_config("demo", [f"output_dir={tmp_path}", *overrides])).clone
    runs: list[tuple[str, str | None]] = []
    steps: list[int] = []
    train_bc, forward = bc.train_bc, OasisPolicy.forward

    def tracked(bc_cfg, *, resume=None):
        runs.append((Path(bc_cfg.output_dir).name, resume or bc_cfg.resume))
        steps.clear()
        return train_bc(bc_cfg, resume=resume)

    def counted(self, batch, reduction="mean"):
        steps.append(len(steps) + 1)
        if runs == [("round_0", None), ("round_1", None)] and len(steps) == 3:
            raise KeyboardInterrupt  # a stop half way through round 1's cloning
        return forward(self, batch, reduction)

    def recorded_again(*args, **kwargs):
        raise AssertionError("round 1's episodes were recorded again")

    monkeypatch.setattr(bc, "train_bc", tracked)
    monkeypatch.setattr(OasisPolicy, "forward", counted)
    with pytest.raises(KeyboardInterrupt):
        stages.train_clone(rounds)
    assert episodes(tmp_path / "bc" / "round_1" / "dataset") == 4  # 2 demonstrations, 2 DAgger
    monkeypatch.setattr(stages, "record_demonstrations", recorded_again)
    assert stages.train_clone(rounds) == tmp_path / "bc" / "round_1" / "policy"
    assert runs[2:] == [("round_1", "latest")]  # round 0 reused, round 1 resumed
    assert steps == [1, 2]  # round 1's steps 3 and 4
    assert (tmp_path / "bc" / "round_1" / "policy" / "model.safetensors").exists()


def test_a_stop_while_a_round_records_loses_only_its_unfinished_episodes(
    tiny_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A Ctrl-C in DAgger round 1's recording, then a kill in the next run's (which leaves a
    partial folder behind): the demonstrations stay byte for byte as they were, and the run
    after records the round whole."""
    from oasis_torchrl.data import LeRobotRecorder

    dataset = tmp_path / "demos"
    shutil.copytree(tiny_dataset, dataset)
    before = fingerprint(dataset)
    settings = [f"output_dir={tmp_path}", *TINY_PIPELINE, "dagger.episodes=4"]
    rounds = plan_run(load_config("demo", settings)).clone
    round_1 = tmp_path / "bc" / "round_1"
    write = LeRobotRecorder.write

    def stopped(self, batch):
        if self.episodes_written:  # two of the round's episodes written, two running
            raise KeyboardInterrupt
        return write(self, batch)

    monkeypatch.setattr(LeRobotRecorder, "write", stopped)
    with pytest.raises(KeyboardInterrupt):
        stages.train_clone(rounds)
    assert (tmp_path / "bc" / "round_0" / "policy").exists() and not (round_1 / "dagger").exists()
    assert not any(round_1.glob(".*partial"))  # a stop that ran Python's cleanup leaves none
    killed = round_1 / ".dagger.partial"  # what a kill mid-recording leaves instead
    shutil.copytree(tiny_dataset, killed)
    (killed / "meta" / "info.json").write_text("{")
    monkeypatch.setattr(LeRobotRecorder, "write", write)
    assert stages.train_clone(rounds) == round_1 / "policy"
    assert fingerprint(dataset) == before
    assert episodes(round_1 / "dagger") == 4 and episodes(round_1 / "dataset") == 6
    assert not killed.exists()


def test_a_policy_named_twice_is_evaluated_once_and_the_last_recorded(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    opened = []
    for_driver = stages.Evaluator.for_driver

    def counting_for_driver(env_cfg, eval_cfg, driver, **kwargs):
        opened.append(eval_cfg.rerun)
        return for_driver(env_cfg, eval_cfg, driver, **kwargs)

    monkeypatch.setattr(stages.Evaluator, "for_driver", counting_for_driver)
    rerun = tmp_path / "eval.rrd"
    cfg = load_config("demo", [*TINY_PIPELINE, f"output_dir={tmp_path}", f"eval.rerun={rerun}"])
    slow, fast = "constant:throttle=0.5", "constant:throttle=1.0"
    policies = {"slow": slow, "fast": fast, "again": fast}
    results = stages.evaluate_all(EvaluationPlan.of(cfg), policies, record=True)
    assert opened == [None, str(rerun)]  # the last name's policy, recorded the first time
    assert results["again"] == results["fast"] != results["slow"]
    assert results["again"] is not results["fast"]  # separate rows of the summary
    assert rerun.stat().st_size > 0


def test_demo_command_rejects_a_bad_key_before_writing(tmp_path: Path) -> None:
    assert main(["demo", f"output_dir={tmp_path / 'out'}", "record.episode=3"]) == 2
    assert not (tmp_path / "out").exists()
