"""The driving network and its TorchRL actor-critic wrappers (no env needed)."""

from __future__ import annotations

import math

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
from oasis_torchrl.models.config import HEADS
from oasis_torchrl.models.network import LOC_BOUND, TARGET_BOUND

SIZE = (32, 48)


def _frames(batch: tuple[int, ...], frames: int = 2, cameras: int = 3) -> list[torch.Tensor]:
    return [torch.rand(*batch, frames, 3, *SIZE) for _ in range(cameras)]


def _pixels(net: DrivingNet, batch: int) -> TensorDict:
    """Env-style observation: the frame stack, uint8 [B, 2, H, W, 3] per camera, and a state."""
    stack = {
        camera: torch.randint(0, 256, (batch, 2, *SIZE, 3), dtype=torch.uint8)
        for camera in net.config.cameras
    }
    return TensorDict({"frame_stack": stack, "state": torch.rand(batch, 2) * 2 - 1}, [batch])


def _trained_looking(net: DrivingNet) -> DrivingNet:
    with torch.no_grad():
        net.actor[-1].weight.normal_()  # leave the near-zero initialisation
    return net


@pytest.mark.parametrize("shared", [True, False])
def test_encoder_keeps_leading_dims(shared: bool) -> None:
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=shared))
    assert encoder(_frames((2, 5))).shape == (2, 5, 3 * 128)


def test_separate_weights_keep_cameras_apart() -> None:
    torch.manual_seed(0)
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=False))
    frames = _frames((4,))
    base = encoder(frames).view(4, 3, -1)
    frames[0] = torch.rand_like(frames[0])
    changed = encoder(frames).view(4, 3, -1)
    assert not torch.allclose(base[:, 0], changed[:, 0])
    torch.testing.assert_close(base[:, 1:], changed[:, 1:])


def test_shared_weights_treat_cameras_alike() -> None:
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=True))
    frames = torch.rand(2, 2, 3, *SIZE)
    features = encoder([frames, frames, frames]).view(2, 3, -1)
    torch.testing.assert_close(features[:, 0], features[:, 2])
    separate = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=False))
    assert not torch.allclose(*separate([frames, frames, frames]).view(2, 3, -1)[:, :2].unbind(1))


@pytest.mark.parametrize("shared", [True, False])
def test_env_frames_and_float_frames_give_the_reference_encoding(shared: bool) -> None:
    torch.manual_seed(0)
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE, shared_encoder=shared))
    frames = _frames((2, 5))
    # The layout trained checkpoints expect: channels ordered camera, frame, colour.
    groups = 1 if shared else 3
    stacked = torch.stack(frames, dim=-5).reshape(-1, groups * 2 * 3, *SIZE)
    pooled = encoder.convs((stacked - 0.5) / 0.25).reshape(-1, groups, 64 * 4 * 6)
    projected = torch.einsum("bgk,gkf->bgf", pooled, encoder.project_weight)
    reference = torch.relu(projected + encoder.project_bias).reshape(2, 5, -1)
    torch.testing.assert_close(encoder(frames), reference)
    env_frames = [(x * 255).round().to(torch.uint8).movedim(-3, -1) for x in frames]
    as_float = [x.movedim(-1, -3) / 255.0 for x in env_frames]
    torch.testing.assert_close(encoder(env_frames), encoder(as_float), atol=1e-5, rtol=1e-4)


def test_finer_strides_keep_a_finer_grid_before_the_pool() -> None:
    config = DrivingNetConfig(image_size=(64, 96), encoder_strides=(2, 2, 2))
    encoder = MultiCameraEncoder(config)
    convolutions = [layer for layer in encoder.convs if isinstance(layer, torch.nn.Conv2d)]
    assert [conv.stride for conv in convolutions] == [(2, 2)] * 3
    grid = encoder.convs[:-1](torch.rand(1, 6, 64, 96))
    assert grid.shape[-2:] == (8, 12)  # 64x96 halved three times; the default ends at 8x12 too
    default = MultiCameraEncoder(DrivingNetConfig(image_size=(64, 96)))
    assert default.convs[:2](torch.rand(1, 6, 64, 96)).shape[-2:] == (16, 24)
    assert encoder.convs[:2](torch.rand(1, 6, 64, 96)).shape[-2:] == (32, 48)
    frames = [torch.rand(2, 2, 3, 64, 96) for _ in config.cameras]
    assert encoder(frames).shape == (2, 3 * config.camera_features)


def test_encoder_rejects_wrong_inputs() -> None:
    encoder = MultiCameraEncoder(DrivingNetConfig(image_size=SIZE))
    with pytest.raises(ValueError, match="expected 3 camera images, got 2"):
        encoder(_frames((1,), cameras=2))
    with pytest.raises(ValueError, match=r"camera frames must be float \[\.\.\., 2, 3, H, W\]"):
        encoder(_frames((1,), frames=1))
    channels_first_bytes = [torch.zeros(1, 2, 3, *SIZE, dtype=torch.uint8)] * 3
    with pytest.raises(ValueError, match=r"or uint8 \[\.\.\., 2, H, W, 3\]"):
        encoder(channels_first_bytes)
    mixed = _frames((1,))
    mixed[2] = torch.zeros(1, 2, *SIZE, 3, dtype=torch.uint8)
    with pytest.raises(ValueError, match="every camera's frames must match the first's"):
        encoder(mixed)


def test_the_network_sees_motion_between_frames() -> None:
    torch.manual_seed(0)
    net = _trained_looking(DrivingNet(DrivingNetConfig(image_size=SIZE)))
    still = torch.rand(1, 3, *SIZE).expand(2, 3, *SIZE)
    moving = torch.stack([torch.rand(3, *SIZE), still[0]])
    state = torch.zeros(1, 2)
    chunk_still = net([still.unsqueeze(0)] * 3, state)
    chunk_moving = net([moving.unsqueeze(0)] * 3, state)
    assert not torch.allclose(chunk_still, chunk_moving)
    longer = torch.cat([torch.rand(1, 2, 3, *SIZE), still.unsqueeze(0)], dim=1)  # 4 frames
    torch.testing.assert_close(net([longer] * 3, state), chunk_still)  # the last 2 are used
    with pytest.raises(ValueError, match=r"\[\*B, >=2, 3, H, W\]"):
        net([still[:1]] * 3, state)


@pytest.mark.parametrize("head", HEADS)
def test_deterministic_actor_is_the_bc_chunk(head: str) -> None:
    torch.manual_seed(0)
    net = _trained_looking(DrivingNet(DrivingNetConfig(image_size=SIZE, head=head)))
    td = _pixels(net, 3)
    policy = make_actor_critic(net).policy
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        action = policy(td.clone())["action"]
        frames = [
            td["frame_stack", camera].movedim(-1, -3) / 255.0 for camera in net.config.cameras
        ]
        chunk = net(frames, td["state"])  # what LeRobot's float images give
    torch.testing.assert_close(action, chunk, atol=1e-5, rtol=1e-4)
    assert chunk.abs().max() < 1 and chunk.std() > 0.1


def test_float_images_work_for_a_one_frame_network() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, frames=1))
    images = {camera: torch.rand(2, 3, *SIZE) for camera in net.config.cameras}
    td = TensorDict({"images": images, "state": torch.zeros(2, 2)}, [2])
    assert make_actor_critic(net, image_key="images").policy(td)["action"].shape == (2, 4, 2)


@pytest.mark.parametrize("head", HEADS)
def test_stochastic_actor_samples_in_bounds_with_finite_log_prob(head: str) -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, head=head, init_scale=(2.0, 0.5)))
    modules = make_actor_critic(net)
    td = modules.value(modules.policy(_pixels(net, 64)))
    assert td["action"].shape == (64, 4, 2)
    assert td["action"].abs().max() <= 1.0
    assert torch.isfinite(td["action_log_prob"]).all() and td["action_log_prob"].shape == (64,)
    assert td["state_value"].shape == (64, 1)
    assert td["scale"][..., 0].unique().tolist() == pytest.approx([2.0])  # throttle
    assert td["scale"][..., 1].unique().tolist() == pytest.approx([0.5])  # steering
    components = {"tanh_normal": (), "mixture": (3,)}[head]
    assert td["loc"].shape == (64, *components, 4, 2)
    dist = modules.policy.get_dist(td)
    torch.testing.assert_close(dist.log_prob(td["action"]), td["action_log_prob"])


@pytest.mark.parametrize("head", HEADS)
@pytest.mark.parametrize("init_action", [(0.5, 0.0), (-0.3, 0.69)])
def test_a_fresh_actor_starts_at_its_init_action(
    init_action: tuple[float, float], head: str
) -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, init_action=init_action, head=head))
    chunk = net(_frames((16,)), torch.rand(16, 2))
    expected = torch.tensor(init_action).expand(16, 4, 2)
    torch.testing.assert_close(chunk, expected, atol=0.02, rtol=0)


def test_a_fresh_mixture_spreads_its_components_around_the_init_action() -> None:
    config = DrivingNetConfig(image_size=SIZE, init_action=(0.5, 0.1), init_spread=(0.2, 0.3))
    params = DrivingNet(config).action_params(torch.rand(16, config.features_dim))
    weights = params["logits"].softmax(-1)
    expected = torch.tensor([1.0, math.exp(2.0), 1.0]) / (2.0 + math.exp(2.0))
    torch.testing.assert_close(weights, expected.expand(16, 3), atol=0.01, rtol=0)
    means = torch.tanh(params["loc"]).mean((0, 2))  # [component, action number]
    spread = torch.tensor([[0.3, -0.2], [0.5, 0.1], [0.7, 0.4]])
    torch.testing.assert_close(means, spread, atol=0.02, rtol=0)


@pytest.mark.parametrize(
    ("init_action", "init_spread", "message"),
    [
        ((0.5,), (0.0, 0.3), r"init_action needs 2 values in \[-0.99, 0.99\]"),
        ((0.0, 1.0), (0.0, 0.0), r"init_action needs 2 values in \[-0.99, 0.99\]"),
        ((-0.995, 0.0), (0.0, 0.3), r"init_action needs 2 values in \[-0.99, 0.99\]"),
        ((0.0, 0.8), (0.0, 0.3), r"init_spread needs 2 values >= 0 that keep"),
        ((0.0, 0.0), (0.3,), r"init_spread needs 2 values >= 0 that keep"),
    ],
)
def test_init_action_must_fit_the_actions(
    init_action: tuple[float, ...], init_spread: tuple[float, ...], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        DrivingNetConfig(init_action=init_action, init_spread=init_spread)


def test_set_scale_and_gradients_reach_the_shared_encoder() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE))
    net.set_scale(0.2)
    assert net.log_scale.exp().flatten().tolist() == pytest.approx([0.2] * 24)
    net.set_scale([0.3, 0.05])
    assert net.log_scale.exp()[..., 1].flatten().tolist() == pytest.approx([0.05] * 12)
    for bad in (0.0, [0.3, 0.05, 0.1]):
        with pytest.raises(ValueError, match="scale must be positive, one value or 2"):
            net.set_scale(bad)
    td = make_actor_critic(net).value(_pixels(net, 2))
    td["state_value"].sum().backward()
    assert net.encoder.convs[0].weight.grad.abs().sum() > 0
    assert net.actor[0].weight.grad is None


def test_privileged_critic_takes_extra_inputs_and_the_aux_head_predicts_them() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE))
    with pytest.raises(ValueError, match="no auxiliary head"):
        net.predict_aux(torch.rand(3, net.config.features_dim))
    privileged = net.with_training_heads(4, 4)
    torch.testing.assert_close(privileged.encoder.convs[0].weight, net.encoder.convs[0].weight)
    features = torch.rand(3, net.config.features_dim)
    prediction = privileged.predict_aux(features)
    assert prediction.shape == (3, 4)
    features[:, net.encoder.out_features :] = 7.0  # the state part: not the head's input
    torch.testing.assert_close(privileged.predict_aux(features), prediction)
    deployed = privileged.with_training_heads(0, 0)
    assert deployed.aux is None and set(deployed.state_dict()) == set(net.state_dict())
    assert privileged.value(features, torch.rand(3, 4)).shape == (3, 1)
    with pytest.raises(ValueError, match="the critic takes 4 extra inputs, got None"):
        privileged.value(features)
    td = _pixels(privileged, 3).set("critic_inputs", torch.rand(3, 4))
    modules = make_actor_critic(privileged)
    assert modules.value(modules.policy(td))["state_value"].shape == (3, 1)


def test_training_heads_keep_their_weights_only_where_their_size_stays() -> None:
    clone = DrivingNet(DrivingNetConfig(image_size=SIZE, aux_outputs=4))
    tuned = clone.with_training_heads(4, 4)  # the critic grows, the auxiliary head stays
    torch.testing.assert_close(tuned.aux[0].weight, clone.aux[0].weight)
    assert not torch.equal(tuned.critic[2].weight, clone.critic[2].weight)
    again = tuned.with_training_heads(4, 2)
    torch.testing.assert_close(again.critic[2].weight, tuned.critic[2].weight)
    assert again.aux[-1].weight.shape[0] == 2


def test_the_mixture_commits_to_the_most_probable_component() -> None:
    torch.manual_seed(0)
    net = _trained_looking(DrivingNet(DrivingNetConfig(image_size=SIZE, components=3)))
    features = torch.rand(6, net.config.features_dim)
    params = net.action_params(features)
    chosen = params["logits"].argmax(-1)
    expected = torch.tanh(params["loc"][torch.arange(6), chosen])
    torch.testing.assert_close(net.deterministic_chunk(features), expected)


@pytest.mark.parametrize("head", HEADS)
def test_the_chunk_likelihood_is_the_distributions_density(head: str) -> None:
    torch.manual_seed(0)
    net = _trained_looking(DrivingNet(DrivingNetConfig(image_size=SIZE, head=head)))
    features = torch.rand(5, net.config.features_dim)
    target = torch.rand(5, 4, 2) * 2 - 1
    target[0, 0, 0] = 1.0  # full throttle: scored at the bound the head can reach
    expected = net.distribution(features).log_prob(target.clamp(-TARGET_BOUND, TARGET_BOUND))
    torch.testing.assert_close(net.chunk_log_likelihood(features, target), expected)
    observed = torch.ones(5, 4, dtype=torch.bool)
    observed[:, 3] = False  # the last action is past the episode's end: any value fits
    shifted = target.clone()
    shifted[:, 3] = 0.9
    torch.testing.assert_close(
        net.chunk_log_likelihood(features, target, observed),
        net.chunk_log_likelihood(features, shifted, observed),
    )


def _fit(
    head: str, features: torch.Tensor, targets: torch.Tensor, by_manoeuvre: bool = False
) -> DrivingNet:
    """A small network's actor fitted to ``targets`` [N, 4, 2] seen as ``features``."""
    torch.manual_seed(0)
    config = DrivingNetConfig(image_size=SIZE, head=head, camera_features=8, hidden_dim=32)
    net = DrivingNet(config)
    features = features.expand(-1, net.config.features_dim)
    optimizer = torch.optim.Adam([*net.actor.parameters(), net.log_scale], lr=1e-2)
    for _ in range(300):
        if by_manoeuvre:
            log_likelihood = sum(net.manoeuvre_log_likelihood(features, targets))
        else:
            log_likelihood = net.chunk_log_likelihood(features, targets)
        optimizer.zero_grad()
        (-log_likelihood.mean()).backward()
        optimizer.step()
    return net


def _clone(head: str, targets: torch.Tensor) -> torch.Tensor:
    """Fit the head to ``targets`` [N, 4, 2] seen from one observation; its chunk for it."""
    features = torch.rand(1, 1).expand(len(targets), 1)
    net = _fit(head, features, targets)
    return net.deterministic_chunk(features[:1].expand(1, net.config.features_dim))[0].detach()


def test_a_manoeuvre_is_the_component_nearest_its_steering() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, components=5, init_spread=(0.0, 0.4)))
    chunks = torch.zeros(5, 4, 2)
    chunks[:, :, 1] = torch.tensor([-0.5, -0.15, 0.05, 0.25, 0.9])[:, None]
    assert net.manoeuvre(chunks).tolist() == [0, 1, 2, 3, 4]
    observed = torch.tensor([[True, True, False, False]] * 5)
    chunks[:, 2:, 1] = -1.0  # past the episode's end: left out
    assert net.manoeuvre(chunks, observed).tolist() == [0, 1, 2, 3, 4]
    unspread = DrivingNet(DrivingNetConfig(image_size=SIZE, init_spread=(0.0, 0.0)))
    with pytest.raises(ValueError, match=r"spread over steering \(DrivingNetConfig.init_spread"):
        unspread.manoeuvre(chunks)


def test_the_manoeuvre_likelihood_gives_each_component_one_manoeuvre() -> None:
    # Throttle varies more than steering, in every manoeuvre; fitted jointly with the
    # manoeuvre, the components are left, keep and right and the weights tell them apart from
    # the observation.
    features = torch.linspace(0.0, 1.0, 90)[:, None]
    targets = torch.zeros(90, 4, 2)
    targets[:, :, 0] = torch.where(torch.arange(90) % 2 == 0, 0.9, -0.5)[:, None]
    targets[:30, :, 1], targets[60:, :, 1] = -0.3, 0.3
    net = _fit("mixture", features, targets, by_manoeuvre=True)
    wide = features.expand(-1, net.config.features_dim)
    committed = net.deterministic_chunk(wide)[:, :, 1].mean(-1).detach()
    assert (committed[:20] < -0.2).all() and (committed[70:] > 0.2).all()
    assert committed[35:55].abs().max() < 0.1
    steering = torch.tanh(net.action_params(wide)["loc"][0, :, :, 1].mean(-1))
    assert steering[0] < -0.2 < 0.2 < steering[2] and steering[1].abs() < 0.1


def test_behaviour_cloning_by_likelihood_commits_to_one_side() -> None:
    # The same view, demonstrated half with a left and half with a right lane change.
    targets = torch.zeros(64, 4, 2)
    targets[:, :, 0] = 0.6
    targets[:32, :, 1], targets[32:, :, 1] = -0.3, 0.3
    mixture, unimodal = _clone("mixture", targets), _clone("tanh_normal", targets)
    torch.testing.assert_close(mixture[:, 0], torch.full((4,), 0.6), atol=0.03, rtol=0)
    assert (mixture[:, 1].abs() - 0.3).abs().max() < 0.03  # steers as one demonstration did
    assert unimodal[:, 1].abs().max() < 0.05  # the median of the two: straight ahead


@pytest.mark.parametrize("head", HEADS)
def test_a_saturated_clone_keeps_ppo_ratios_finite(head: str) -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, head=head))
    net.set_scale(0.2)
    modules = make_actor_critic(net)
    with torch.no_grad():
        net.actor[-1].bias.fill_(10.0)  # where L1 on +-1 labels pushes a clone
    with set_exploration_type(ExplorationType.RANDOM):  # as a collector samples
        td = modules.policy(_pixels(net, 256))
    assert td["loc"].max() <= LOC_BOUND
    with torch.no_grad():
        net.actor[-1].bias.add_(0.05)  # one small update
    log_ratio = modules.policy.get_dist(td).log_prob(td["action"]) - td["action_log_prob"]
    assert log_ratio.abs().max() < 0.1  # unbounded: about 28 nats


def test_without_state_the_actions_depend_on_the_cameras_only() -> None:
    net = DrivingNet(DrivingNetConfig(image_size=SIZE, use_state=False)).eval()
    assert net.config.features_dim == 3 * net.config.camera_features
    images = _frames((2,))
    with torch.no_grad():
        chunk = net(images, torch.zeros(2, 2))
        torch.testing.assert_close(net(images, torch.ones(2, 2)), chunk)
        assert not torch.allclose(net(_frames((2,)), torch.zeros(2, 2)), chunk)


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
    with pytest.raises(ValueError, match=r"head must be one of \('tanh_normal', 'mixture'\)"):
        DrivingNetConfig(head="gmm")
    with pytest.raises(ValueError, match=r"init_scale needs 2 values \(one per action number\)"):
        DrivingNetConfig(init_scale=(0.5,))
    with pytest.raises(ValueError, match="components must be positive"):
        DrivingNetConfig(components=0)
    with pytest.raises(ValueError, match=r"encoder_strides needs 3 values among \(1, 2, 4\)"):
        DrivingNetConfig(encoder_strides=(3, 2, 1))


def test_networks_saved_before_the_mixture_head_load() -> None:
    saved = DrivingNet(DrivingNetConfig(image_size=SIZE, head="tanh_normal", init_scale=(0.5, 0.5)))
    values = saved.config.to_dict()
    del values["head"], values["components"]
    values["init_scale"] = 0.5
    net = DrivingNet(DrivingNetConfig.from_dict(values))
    net.load_state_dict(saved.state_dict())
    assert net.config == saved.config
