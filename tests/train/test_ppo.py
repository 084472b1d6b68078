"""PPO on the embedded server at tiny resolution: updates, checkpoints, resume, warm start."""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers.folders import export_lerobot, load_net
from oasis_torchrl.envs.factory import make_env
from oasis_torchrl.envs.transforms import PRIVILEGED_FIELDS
from oasis_torchrl.models import DrivingNet, DrivingNetConfig
from oasis_torchrl.models.checkpoint import load_checkpoint
from oasis_torchrl.train import ppo as ppo_module
from oasis_torchrl.train.ppo import PPOResult, PPOTrainer, build_net

from .conftest import TINY_ENV, tiny_ppo

CAMERAS = ("left_forward", "front", "right_forward")


def _ppo_config(output: Path, total: int, *extra: str):
    extra = (
        "optim.epochs=2",
        "eval.every=1",
        "privileged_critic=true",
        "env.reward.clearance_weight=0.2",
        *extra,
    )
    return load_config("ppo", tiny_ppo(output, total, *extra))


def _csv_values(path: Path) -> list[float]:
    with path.open() as handle:
        return [float(row[1]) for row in csv.reader(handle)]


def test_ppo_updates_checkpoints_and_resumes(tmp_path: Path) -> None:
    overrides = ("optim.lr=2e-4", "optim.critic_lr=1e-3", "network.init_scale=[0.5,0.1]")
    first_half = "optim.anneal_frames=32"  # the resumed run's schedule, stopped half-way
    trainer = PPOTrainer(_ppo_config(tmp_path, 16, *overrides, first_half))
    before = {key: value.clone() for key, value in trainer.net.state_dict().items()}
    result = trainer.run()

    after = result.net.state_dict()
    trained = ("encoder.convs.0.weight", "actor.0.weight", "critic.2.weight", "aux.2.weight")
    for key in (*trained, "log_scale"):
        assert not torch.equal(before[key], after[key]), key
    scale = after["log_scale"]  # optim.pool_scale: one learned value per action number
    torch.testing.assert_close(scale, scale[:1, :1].expand_as(scale))
    assert result.net.config.critic_inputs == len(PRIVILEGED_FIELDS)  # the asymmetric critic
    actor_group, critic_group, scale_group = trainer.update.optimizer.param_groups  # annealed alike
    assert critic_group["lr"] == pytest.approx(5 * actor_group["lr"])
    assert scale_group["lr"] == pytest.approx(50 * actor_group["lr"])  # optim.scale_lr 1e-2
    heads = [*result.net.critic.parameters(), *result.net.aux.parameters()]
    assert {id(parameter) for parameter in critic_group["params"]} == {id(p) for p in heads}
    assert scale_group["params"] == [result.net.log_scale]
    scalars = tmp_path / "logs" / "ppo" / "scalars"
    for name in ("loss_objective", "loss_critic", "loss_entropy", "loss_aux"):
        values = _csv_values(scalars / "loss" / f"{name}.csv")
        assert values and all(math.isfinite(v) for v in values), name
    assert _csv_values(scalars / "eval" / "mean_distance.csv")
    for name in ("collect_s", "update_s", "env_steps_per_s"):
        values = _csv_values(scalars / "time" / f"{name}.csv")
        assert values and all(v > 0 for v in values), name
    throttle = _csv_values(scalars / "policy" / "scale_throttle.csv")
    steering = _csv_values(scalars / "policy" / "scale_steering.csv")
    assert throttle[0] == pytest.approx(0.5, rel=0.05) and steering[0] == pytest.approx(0.1, 0.05)

    state = load_checkpoint(result.checkpoint)
    assert (state["iteration"], state["frames"]) == (1, 16)
    restored = load_net(result.checkpoint)
    for key, value in after.items():
        torch.testing.assert_close(restored.state_dict()[key], value)
    exported = load_net(result.policy_dir)  # LeRobot folder: no privileged critic
    assert exported.config.critic_inputs == 0
    torch.testing.assert_close(exported.state_dict()["actor.2.bias"], after["actor.2.bias"])

    resumed = PPOTrainer(_ppo_config(tmp_path, 32, *overrides, "resume=latest")).run()
    state = load_checkpoint(resumed.checkpoint)
    assert (state["iteration"], state["frames"]) == (2, 32)
    assert [entry["frames"] for entry in resumed.history] == [16, 32]
    learning_rates = _csv_values(scalars / "optim" / "lr.csv")
    assert learning_rates == pytest.approx([2e-4 * 0.5, 2e-4 * 0.05])  # one schedule over 32
    assert not torch.equal(resumed.net.state_dict()["actor.0.weight"], after["actor.0.weight"])

    old = torch.load(resumed.checkpoint, weights_only=False)  # one parameter group: an old run's
    old["optimizer"]["param_groups"] = old["optimizer"]["param_groups"][:1]
    torch.save(old, tmp_path / "old.pt")
    with pytest.raises(ValueError, match=r"cannot resume the optimizer of .*old\.pt"):
        PPOTrainer(_ppo_config(tmp_path, 48, f"resume={tmp_path / 'old.pt'}"))


def test_selection_seeds_choose_the_kept_policy(tmp_path: Path) -> None:
    cfg = _ppo_config(
        tmp_path,
        48,
        "eval.selection_seeds=[5]",
        "eval.max_steps=4",
        "checkpoint.keep_evaluated=true",
        "optim.pool_scale=false",
    )
    result = PPOTrainer(cfg).run()
    assert result.net.log_scale[..., 1].unique().numel() > 1  # one scale per chunk entry

    *periodic, final = result.history
    assert [entry["seeds"] for entry in periodic] == [[5]] * 3
    assert [episode["episode_seed"] for episode in final["per_episode"]] == [
        episode["episode_seed"] for episode in result.final_eval.to_dict()["per_episode"]
    ]
    assert final["seeds"] == [1000] and final["frames"] == 48
    assert [entry["policy_frames"] for entry in periodic] == [16, 32, 48]
    distances = [entry["mean_distance"] for entry in periodic]
    chosen = periodic[distances.index(max(distances))]  # the first of equals: no later tie wins
    assert result.checkpoint == tmp_path / "checkpoints" / "best.pt"
    best = load_checkpoint(result.checkpoint)
    assert best["frames"] == chosen["frames"] == final["policy_frames"]
    assert best["selection"]["mean_distance"] == chosen["mean_distance"]
    for key, value in result.net.state_dict().items():
        torch.testing.assert_close(value, best["net_state"][key])
    exported = load_net(result.policy_dir)
    torch.testing.assert_close(
        exported.state_dict()["actor.2.bias"], best["net_state"]["actor.2.bias"]
    )
    latest = load_checkpoint(tmp_path / "checkpoints" / "latest.pt")  # the training state
    assert (latest["frames"], latest["best_selection"]) == (48, max(distances))
    for entry in periodic:  # every evaluated policy kept, e.g. to choose within a smaller budget
        kept = load_checkpoint(tmp_path / "checkpoints" / f"frames_{entry['frames']}.pt")
        assert kept["evaluation"]["mean_distance"] == entry["mean_distance"]
    torch.testing.assert_close(
        kept["net_state"]["actor.2.bias"], latest["net_state"]["actor.2.bias"]
    )

    with pytest.raises(ValueError, match=r"eval\.selection_seeds must be null or a non-empty"):
        _ppo_config(tmp_path, 48, "eval.selection_seeds=[]")
    for bad in ("2000", "[a]"):  # a typed setting: refused where it is set, naming it
        with pytest.raises(ValueError, match=rf"eval\.selection_seeds={re.escape(bad)}: "):
            _ppo_config(tmp_path, 48, f"eval.selection_seeds={bad}")


def _fine_tune(tmp_path: Path, *overrides: str) -> tuple[DrivingNet, PPOResult]:
    """A fresh network exported as a LeRobot policy, then fine-tuned 32 env steps from it
    with selection seeds; the network and the run's result."""
    source = DrivingNet(DrivingNetConfig(image_size=(32, 48)))
    folder = export_lerobot(source, tmp_path / "bc_policy")
    cfg = _ppo_config(
        tmp_path / "run",
        32,
        f"init_from={folder}",
        "eval.selection_seeds=[5]",
        "eval.max_steps=4",
        *overrides,
    )
    return source, PPOTrainer(cfg).run()


def test_a_warm_start_is_the_first_candidate_of_the_selection(tmp_path: Path) -> None:
    """Fine-tuning keeps the policy it started from unless a later one beats it on the
    selection seeds: the warm start is rated before any update."""
    source, result = _fine_tune(tmp_path, "eval.every=2")

    *periodic, final = result.history
    assert [entry["policy_frames"] for entry in periodic] == [0, 32]
    distances = [entry["mean_distance"] for entry in periodic]
    best = load_checkpoint(result.checkpoint)
    assert best["frames"] == periodic[distances.index(max(distances))]["frames"]
    assert final["policy_frames"] == best["frames"]
    if best["frames"] == 0:  # the warm start kept: its weights, not the updated ones
        torch.testing.assert_close(
            result.net.state_dict()["actor.2.bias"], source.state_dict()["actor.2.bias"]
        )


def test_a_margin_keeps_the_warm_start_against_gains_within_noise(tmp_path: Path) -> None:
    """With ``eval.selection_margin``, a later policy must beat the kept one by that many
    standard errors of the paired difference; no gain over two episodes is a million."""
    source, result = _fine_tune(
        tmp_path, "eval.selection_margin=1e6", "eval.episodes=2", "eval.every=1"
    )
    *periodic, final = result.history
    assert [entry["policy_frames"] for entry in periodic] == [0, 16, 32]
    assert load_checkpoint(result.checkpoint)["frames"] == final["policy_frames"] == 0
    torch.testing.assert_close(
        result.net.state_dict()["actor.2.bias"], source.state_dict()["actor.2.bias"]
    )
    latest = load_checkpoint(tmp_path / "run" / "checkpoints" / "latest.pt")
    assert latest["kept_selection"]["mean_distance"] == periodic[0]["mean_distance"]

    with pytest.raises(
        ValueError, match=r"eval\.selection_margin must be a number >= 0\.0, got -1"
    ):
        _ppo_config(tmp_path, 32, "eval.selection_margin=-1")


def test_an_unchanged_policy_is_not_evaluated_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The critic-only warm-up leaves the actor as it was, so the evaluation after it is the
    warm start's, reused; without ``eval.final`` the run ends without evaluating on ``seeds``."""
    evaluated = []
    evaluate = ppo_module.Evaluator.evaluate

    def counting_evaluate(self, policy, seeds):
        evaluated.append(tuple(seeds))
        return evaluate(self, policy, seeds)

    monkeypatch.setattr(ppo_module.Evaluator, "evaluate", counting_evaluate)
    _, result = _fine_tune(
        tmp_path, "loss.critic_warmup_iters=1", "eval.every=1", "eval.final=false"
    )
    assert [entry["frames"] for entry in result.history] == [0, 16, 32]
    warm_start, after_warm_up, _ = result.history
    assert after_warm_up["per_episode"] == warm_start["per_episode"]
    assert evaluated == [(5,), (5,)]  # the warm start and the policy of 32 env steps
    assert result.final_eval is None


def test_warm_start_loads_a_lerobot_policy_and_resets_the_scale(tmp_path: Path) -> None:
    source = DrivingNet(DrivingNetConfig(image_size=(32, 48), init_scale=(1.5, 0.3)))
    folder = export_lerobot(source, tmp_path / "bc_policy")
    cfg = load_config("ppo", [*TINY_ENV, f"init_from={folder}", "warm_start_scale=[0.25,0.05]"])
    net = build_net(cfg, CAMERAS)
    torch.testing.assert_close(net.encoder.convs[0].weight, source.encoder.convs[0].weight)
    assert net.log_scale.exp()[..., 0].flatten().tolist() == pytest.approx([0.25] * 12)
    assert net.log_scale.exp()[..., 1].flatten().tolist() == pytest.approx([0.05] * 12)
    kept = build_net(OmegaConf.merge(cfg, {"warm_start_scale": None}), CAMERAS)
    torch.testing.assert_close(kept.log_scale, source.log_scale)  # null: the clone's own scale
    privileged = build_net(OmegaConf.merge(cfg, {"privileged_critic": True}), CAMERAS)
    assert privileged.critic[0].in_features == source.critic[0].in_features + len(PRIVILEGED_FIELDS)
    torch.testing.assert_close(privileged.actor[0].weight, source.actor[0].weight)

    wrong_size = load_config("ppo", [f"init_from={folder}"])  # the env's default 64x96
    with pytest.raises(ValueError, match=r"set env\.image_size to the network's size"):
        build_net(wrong_size, CAMERAS)


def test_a_refused_network_closes_the_env_it_opened(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    opened = []

    def recording_make_env(*args, **kwargs):
        opened.append(make_env(*args, **kwargs))
        return opened[-1]

    monkeypatch.setattr(ppo_module, "make_env", recording_make_env)
    folder = export_lerobot(DrivingNet(DrivingNetConfig(image_size=(16, 24))), tmp_path / "small")
    with pytest.raises(ValueError, match=r"set env\.image_size to the network's size"):
        PPOTrainer(_ppo_config(tmp_path / "run", 16, f"init_from={folder}"))
    assert len(opened) == 1 and opened[0].is_closed  # its embedded server stopped with it
