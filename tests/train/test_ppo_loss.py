"""DrivingPPOLoss: the encoder once per minibatch gives TorchRL's ClipPPOLoss exactly."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from tensordict import TensorDict
from torchrl.objectives import ClipPPOLoss

from oasis_torchrl.config import load_config
from oasis_torchrl.envs.factory import make_env
from oasis_torchrl.envs.transforms import PRIVILEGED_FIELDS
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.models.config import HEADS, TANH_NORMAL
from oasis_torchrl.train.ppo_loss import DrivingPPOLoss

from .conftest import TINY_ENV

SIZE = (32, 48)
PRIVILEGED = len(PRIVILEGED_FIELDS)
ASYMMETRIC = DrivingNetConfig(image_size=SIZE, critic_inputs=PRIVILEGED, aux_outputs=PRIVILEGED)
PPO_KWARGS = {"clip_epsilon": 0.2, "entropy_coeff": 0.0, "normalize_advantage": True}


@pytest.fixture(scope="module")
def rollout() -> TensorDict:
    """Six steps of two rows on the embedded server, as a collector stores them (with the
    acting pass's features, detached); advantages and targets are random."""
    env = make_env(load_config("ppo", TINY_ENV).env, num_envs=2, privileged=True)
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, critic_inputs=PRIVILEGED))
    try:
        steps = env.rollout(6, make_actor_critic(net).policy, break_when_any_done=False)
    finally:
        env.close()
    generator = torch.Generator().manual_seed(0)
    steps["advantage"] = torch.randn(*steps.shape, 1, generator=generator)
    steps["value_target"] = torch.randn(*steps.shape, 1, generator=generator)
    return steps.exclude("next").reshape(-1).detach()


def _gradients(net: DrivingNet, loss: torch.Tensor) -> dict[str, torch.Tensor]:
    net.zero_grad(set_to_none=True)
    loss.backward()
    return {name: p.grad.clone() for name, p in net.named_parameters() if p.grad is not None}


@pytest.mark.parametrize("head", HEADS)
def test_matches_clip_ppo_loss_over_the_full_operators(rollout: TensorDict, head: str) -> None:
    torch.manual_seed(0)
    net = DrivingNet(dataclasses.replace(ASYMMETRIC, head=head))
    modules = make_actor_critic(net)
    if head == TANH_NORMAL:  # the rollout's actions and log-probabilities are the mixture's
        with torch.no_grad():
            rollout = modules.policy(rollout.clone())
    terms = ("loss_objective", "loss_critic", "loss_entropy")

    reference = ClipPPOLoss(modules.policy, modules.value, **PPO_KWARGS)(rollout.clone())
    ours = DrivingPPOLoss(modules, aux_coeff=0.0, **PPO_KWARGS)(rollout.clone())
    for key in terms:
        torch.testing.assert_close(ours[key], reference[key])
    expected = _gradients(net, sum(reference[key] for key in terms))
    got = _gradients(net, sum(ours[key] for key in terms))
    assert got.keys() == expected.keys() and "encoder.convs.0.weight" in got
    for name, gradient in expected.items():
        torch.testing.assert_close(got[name], gradient, msg=name)


def test_adds_the_weighted_auxiliary_loss_only_with_the_head(rollout: TensorDict) -> None:
    net = DrivingNet(ASYMMETRIC)
    loss = DrivingPPOLoss(make_actor_critic(net), aux_coeff=2.0, **PPO_KWARGS)
    losses = loss(rollout)
    assert loss.terms[-1] == "loss_aux"
    with torch.no_grad():
        features = make_actor_critic(net).features(rollout.clone())["features"]
    expected = 2.0 * torch.nn.functional.mse_loss(
        net.predict_aux(features), rollout["critic_inputs"]
    )
    torch.testing.assert_close(losses["loss_aux"].detach(), expected)

    plain = DrivingNet(DrivingNetConfig(image_size=SIZE, critic_inputs=PRIVILEGED))
    without = DrivingPPOLoss(make_actor_critic(plain), aux_coeff=2.0, **PPO_KWARGS)
    assert "loss_aux" not in without(rollout).keys()
    assert "loss_aux" not in without.terms


def test_leaves_the_callers_minibatch_alone(rollout: TensorDict) -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, critic_inputs=PRIVILEGED))
    stored = rollout["features"].clone()
    losses = DrivingPPOLoss(make_actor_critic(net), **PPO_KWARGS)(rollout)
    assert losses["loss_objective"].requires_grad
    assert not rollout["features"].requires_grad
    torch.testing.assert_close(rollout["features"], stored)
