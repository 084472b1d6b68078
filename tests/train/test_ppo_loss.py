"""DrivingPPOLoss: the encoder once per minibatch gives TorchRL's ClipPPOLoss exactly."""

from __future__ import annotations

import torch
from tensordict import TensorDict
from torchrl.objectives import ClipPPOLoss

from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.train.ppo_loss import DrivingPPOLoss

SIZE = (32, 48)
PPO_KWARGS = {"clip_epsilon": 0.2, "entropy_coeff": 0.0, "normalize_advantage": True}


def _batch(net: DrivingNet, rows: int = 12) -> TensorDict:
    generator = torch.Generator().manual_seed(0)
    pixels = {
        camera: torch.randint(0, 256, (rows, 4, *SIZE, 3), dtype=torch.uint8, generator=generator)
        for camera in net.config.cameras
    }
    batch = TensorDict(
        {"pixels": pixels, "state": torch.rand(rows, 2), "critic_inputs": torch.rand(rows, 4)},
        [rows],
    )
    with torch.no_grad():
        batch = make_actor_critic(net).policy(batch)
    batch["advantage"] = torch.randn(rows, 1, generator=generator)
    batch["value_target"] = torch.randn(rows, 1, generator=generator)
    # What a collector stores: the features of the acting pass, detached and soon stale.
    batch["features"] = torch.zeros_like(batch["features"])
    return batch


def _gradients(net: DrivingNet, loss: torch.Tensor) -> dict[str, torch.Tensor]:
    net.zero_grad(set_to_none=True)
    loss.backward()
    return {name: p.grad.clone() for name, p in net.named_parameters() if p.grad is not None}


def test_matches_clip_ppo_loss_over_the_full_operators() -> None:
    torch.manual_seed(0)
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, critic_inputs=4, aux_outputs=4))
    modules = make_actor_critic(net)
    batch = _batch(net)
    terms = ("loss_objective", "loss_critic", "loss_entropy")

    reference = ClipPPOLoss(modules.policy, modules.value, **PPO_KWARGS)(batch.clone())
    ours = DrivingPPOLoss(modules, aux_coeff=0.0, **PPO_KWARGS)(batch.clone())
    for key in terms:
        torch.testing.assert_close(ours[key], reference[key])
    expected = _gradients(net, sum(reference[key] for key in terms))
    got = _gradients(net, sum(ours[key] for key in terms))
    assert got.keys() == expected.keys() and "encoder.convs.0.weight" in got
    for name, gradient in expected.items():
        torch.testing.assert_close(got[name], gradient, msg=name)


def test_adds_the_weighted_auxiliary_loss_only_with_the_head() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, critic_inputs=4, aux_outputs=4))
    batch = _batch(net)
    loss = DrivingPPOLoss(make_actor_critic(net), aux_coeff=2.0, **PPO_KWARGS)
    losses = loss(batch)
    assert loss.terms[-1] == "loss_aux"
    with torch.no_grad():
        prediction = net.predict_aux(make_actor_critic(net).features(batch.clone())["features"])
    expected = 2.0 * torch.nn.functional.mse_loss(prediction, batch["critic_inputs"])
    torch.testing.assert_close(losses["loss_aux"].detach(), expected)

    plain = DrivingNet(DrivingNetConfig(image_size=SIZE, critic_inputs=4))
    without = DrivingPPOLoss(make_actor_critic(plain), aux_coeff=2.0, **PPO_KWARGS)
    assert "loss_aux" not in without(_batch(plain)).keys()
    assert "loss_aux" not in without.terms


def test_leaves_the_callers_minibatch_alone() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, critic_inputs=4))
    batch = _batch(net)
    DrivingPPOLoss(make_actor_critic(net), **PPO_KWARGS)(batch)
    assert not batch["features"].requires_grad
    assert batch["features"].abs().sum() == 0
