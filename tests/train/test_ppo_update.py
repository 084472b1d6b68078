"""PPOUpdate without an env: the learning-rate schedule, the critic warm-up, the KL stop and the
skipping of non-finite steps, on a batch the real policy collected from random frames."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from oasis_torchrl.config import load_config
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.train.ppo_update import PPOUpdate

ROWS, TIME = 2, 8


def _update(*overrides: str) -> PPOUpdate:
    torch.manual_seed(0)
    net = DrivingNet(DrivingNetConfig(image_size=(32, 48), critic_inputs=10, aux_outputs=10))
    cfg = load_config("ppo", ["optim.mini_batch_size=4", "optim.epochs=2", *overrides])
    return PPOUpdate(make_actor_critic(net), cfg, anneal_frames=1000)


def _observations(net: DrivingNet) -> TensorDict:
    frames = torch.randint(0, 255, (ROWS, TIME, 2, 32, 48, 3), dtype=torch.uint8)
    return TensorDict(
        {
            "frame_stack": {camera: frames for camera in net.config.cameras},
            "state": torch.zeros(ROWS, TIME, 2),
            "critic_inputs": torch.rand(ROWS, TIME, 10),
        },
        [ROWS, TIME],
    )


def _batch(update: PPOUpdate) -> TensorDict:
    """A ``[rows, time]`` batch as the collector gives it: actions and log-probabilities from
    the policy, rewards and a next observation per step."""
    modules = make_actor_critic(update.net)
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        batch = modules.policy(_observations(update.net))
    ended = torch.zeros(ROWS, TIME, 1, dtype=torch.bool)
    batch["next"] = _observations(update.net).update(
        {"reward": torch.randn(ROWS, TIME, 1), "done": ended, "terminated": ended}
    )
    return batch


def _weights(update: PPOUpdate) -> dict[str, torch.Tensor]:
    return {key: value.clone() for key, value in update.net.state_dict().items()}


def test_the_learning_rates_anneal_over_the_run_to_five_percent() -> None:
    update = _update()
    update(_batch(update), frames=500)
    assert [group["lr"] for group in update.optimizer.param_groups] == pytest.approx(
        [1.5e-4, 5e-4, 5e-3]
    )
    metrics = update(_batch(update), frames=1000)
    assert metrics["optim/lr"] == pytest.approx(0.05 * 3e-4)
    assert metrics["optim/updates"] == 2 * ROWS * TIME / 4  # epochs x minibatches


def test_a_schedule_must_be_positive() -> None:
    with pytest.raises(
        ValueError, match=r"optim\.anneal_frames must be an integer > 0 or null, got 0"
    ):
        load_config("ppo", ["optim.anneal_frames=0"])


def test_a_critic_warm_up_trains_the_critic_head_alone() -> None:
    update = _update()
    before = _weights(update)
    update(_batch(update), frames=100, critic_only=True)
    after = update.net.state_dict()
    assert not torch.equal(before["critic.0.weight"], after["critic.0.weight"])
    for key in ("encoder.convs.0.weight", "actor.0.weight", "log_scale"):
        assert torch.equal(before[key], after[key]), key


def test_non_finite_steps_are_skipped_and_the_weights_stay_finite() -> None:
    update = _update()
    batch = _batch(update)
    batch["action_log_prob"] = torch.full_like(batch["action_log_prob"], float("nan"))
    before = _weights(update)
    metrics = update(batch, frames=100)
    assert metrics["optim/skipped_minibatches"] == 2 * ROWS * TIME / 4
    assert metrics["optim/updates"] == 0
    for key, value in update.net.state_dict().items():
        assert torch.equal(before[key], value), key
