"""The driving network and its TorchRL actor-critic wrappers (no env needed)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from oasis_torchrl.models import (
    DrivingNet,
    DrivingNetConfig,
    MultiCameraEncoder,
    make_actor_critic,
)

SIZE = (32, 48)


def _images(batch: tuple[int, ...], cameras: int = 3) -> list[torch.Tensor]:
    return [torch.rand(*batch, 3, *SIZE) for _ in range(cameras)]


def _observation(net: DrivingNet, batch: int) -> TensorDict:
    images = dict(zip(net.config.cameras, _images((batch,)), strict=True))
    return TensorDict({"images": images, "state": torch.rand(batch, 2) * 2 - 1}, [batch])


@pytest.mark.parametrize("shared", [True, False])
def test_encoder_keeps_leading_dims(shared: bool) -> None:
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=shared))
    assert encoder(_images((2, 5))).shape == (2, 5, 3 * 128)


def test_separate_weights_keep_cameras_apart() -> None:
    torch.manual_seed(0)
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=False))
    images = _images((4,))
    base = encoder(images).view(4, 3, -1)
    images[0] = torch.rand_like(images[0])
    changed = encoder(images).view(4, 3, -1)
    assert not torch.allclose(base[:, 0], changed[:, 0])
    torch.testing.assert_close(base[:, 1:], changed[:, 1:])


def test_shared_weights_treat_cameras_alike() -> None:
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=True))
    image = torch.rand(2, 3, *SIZE)
    features = encoder([image, image, image]).view(2, 3, -1)
    torch.testing.assert_close(features[:, 0], features[:, 2])
    separate = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=False))
    assert not torch.allclose(*separate([image, image, image]).view(2, 3, -1)[:, :2].unbind(1))


def test_encoder_rejects_wrong_camera_count() -> None:
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE))
    with pytest.raises(ValueError, match="expected 3 camera images, got 2"):
        encoder(_images((1,), cameras=2))


def test_deterministic_actor_is_the_bc_chunk() -> None:
    torch.manual_seed(0)
    net = DrivingNet(DrivingNetConfig(image_size=SIZE))
    with torch.no_grad():
        net.actor[-1].weight.normal_()  # leave the near-zero initialisation
    td = _observation(net, 3)
    policy = make_actor_critic(net).policy
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        action = policy(td.clone())["action"]
        chunk = net([td["images", c] for c in net.config.cameras], td["state"])
    torch.testing.assert_close(action, chunk)
    assert chunk.abs().max() < 1 and chunk.std() > 0.1


def test_stochastic_actor_samples_in_bounds_with_finite_log_prob() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, init_scale=2.0))
    modules = make_actor_critic(net)
    td = modules.value(modules.policy(_observation(net, 64)))
    assert td["action"].shape == (64, 4, 2)
    assert td["action"].abs().max() <= 1.0
    assert torch.isfinite(td["action_log_prob"]).all() and td["action_log_prob"].shape == (64,)
    assert td["state_value"].shape == (64, 1)
    assert td["scale"].flatten().unique().tolist() == pytest.approx([2.0])


def test_set_scale_and_gradients_reach_the_shared_encoder() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE))
    net.set_scale(0.2)
    assert net.log_scale.exp().flatten().tolist() == pytest.approx([0.2] * 8)
    with pytest.raises(ValueError, match="scale must be positive"):
        net.set_scale(0.0)
    td = make_actor_critic(net).value(_observation(net, 2))
    td["state_value"].sum().backward()
    assert net.encoder.convs[0].weight.grad.abs().sum() > 0
    assert net.actor[0].weight.grad is None


def test_config_round_trip_and_validation() -> None:
    config = DrivingNetConfig(cameras=("front",), image_size=(48, 64), shared_encoder=False)
    assert DrivingNetConfig.from_dict(config.to_dict()) == config
    assert DrivingNet(config).config.features_dim == 128 + 2
    with pytest.raises(ValueError, match=r"unknown DrivingNetConfig fields \['depth'\]"):
        DrivingNetConfig.from_dict({"depth": 3})
    with pytest.raises(ValueError, match="encoder_channels must be positive"):
        DrivingNetConfig(encoder_channels=(8, 0, 8))
    with pytest.raises(ValueError, match="duplicates"):
        DrivingNetConfig(cameras=("front", "front"))
