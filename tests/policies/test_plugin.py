"""The LeRobot plugin: registration, the action queue, save/load, the loss, its defaults.

That ``lerobot-train --policy.type=oasis`` and ``oasis-torchrl train bc`` build the same policy
is checked in ``tests/lerobot_tools/test_eval_train.py``, on that module's ``lerobot-train`` run."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.factory import get_policy_class, make_pre_post_processors
from lerobot.utils.import_utils import register_third_party_plugins
from lerobot_policy_oasis import OasisConfig, OasisPolicy
from lerobot_policy_oasis.configuration_oasis import NETWORK_FIELDS, TRAINING_FIELDS
from omegaconf import OmegaConf

from oasis_torchrl.config import load_config
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, PRIVILEGED_KEY

CAMERAS = ("left_forward", "front", "right_forward")
SIZE = (32, 48)


def _config(action_dim: int = 2, **overrides: object) -> OasisConfig:
    inputs = {
        f"observation.images.{camera}": PolicyFeature(FeatureType.VISUAL, (3, *SIZE))
        for camera in CAMERAS
    }
    inputs["observation.state"] = PolicyFeature(FeatureType.STATE, (2,))
    outputs = {"action": PolicyFeature(FeatureType.ACTION, (action_dim,))}
    return OasisConfig(
        device="cpu", input_features=inputs, output_features=outputs, image_size=SIZE, **overrides
    )


def _observation(size: int = 2, seed: int = 0) -> dict[str, torch.Tensor]:
    """One step's observation, as an env gives it to ``select_action``."""
    generator = torch.Generator().manual_seed(seed)
    batch = {
        f"observation.images.{camera}": torch.rand(size, 3, *SIZE, generator=generator)
        for camera in CAMERAS
    }
    batch["observation.state"] = torch.rand(size, 2, generator=generator) * 2 - 1
    return batch


def _stacked(*observations: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Observations stacked on dim 1, as a dataset batch holds them."""
    return {key: torch.stack([o[key] for o in observations], dim=1) for key in observations[0]}


def _policy(**overrides: object) -> OasisPolicy:
    torch.manual_seed(0)
    policy = OasisPolicy(_config(**overrides))
    with torch.no_grad():
        policy.model.actor[-1].weight.normal_()  # leave the near-zero initialisation
    return policy.eval()


def test_lerobot_discovers_the_plugin() -> None:
    register_third_party_plugins()
    assert get_policy_class("oasis") is OasisPolicy
    pre, post = make_pre_post_processors(_config())
    assert any(type(step).__name__ == "ResizeFramesProcessorStep" for step in pre.steps)
    assert type(post.steps[0]).__name__ == "UnnormalizerProcessorStep"


def test_select_action_serves_the_queued_chunk_and_remembers_frames() -> None:
    policy = _policy()
    steps = [_observation(seed=k) for k in range(6)]
    chunk = policy.predict_action_chunk(_stacked(steps[0], steps[0]))  # reset: no motion yet
    served = [policy.select_action(step) for step in steps[:4]]
    torch.testing.assert_close(torch.stack(served, dim=1), chunk)  # later observations queued
    # The next chunk sees the observation one chunk (4 calls) earlier and the current one.
    expected = policy.predict_action_chunk(_stacked(steps[0], steps[4]))[:, 0]
    torch.testing.assert_close(policy.select_action(steps[4]), expected)
    assert not torch.allclose(
        expected, policy.predict_action_chunk(_stacked(steps[3], steps[4]))[:, 0]
    )
    policy.reset()
    torch.testing.assert_close(policy.select_action(steps[0]), chunk[:, 0])


def test_n_action_steps_limits_the_queue() -> None:
    policy = _policy(n_action_steps=2)
    steps = [_observation(seed=k) for k in range(7)]
    chunk = policy.predict_action_chunk(_stacked(steps[0], steps[0]))
    served = [policy.select_action(steps[0]), policy.select_action(steps[1])]
    torch.testing.assert_close(torch.stack(served, dim=1), chunk[:, :2])
    # Before 4 calls, the history before the episode's first observation is that observation.
    expected = policy.predict_action_chunk(_stacked(steps[0], steps[2]))[:, 0]
    torch.testing.assert_close(policy.select_action(steps[2]), expected)
    policy.select_action(steps[3])
    expected = policy.predict_action_chunk(_stacked(steps[0], steps[4]))[:, 0]
    torch.testing.assert_close(policy.select_action(steps[4]), expected)
    policy.select_action(steps[5])
    expected = policy.predict_action_chunk(_stacked(steps[2], steps[6]))[:, 0]
    torch.testing.assert_close(policy.select_action(steps[6]), expected)


def test_save_and_load_round_trip(tmp_path: Path) -> None:
    policy = _policy(shared_encoder=False, camera_features=32, use_state=False)
    policy.save_pretrained(tmp_path)
    loaded = OasisPolicy.from_pretrained(tmp_path)
    assert loaded.config.shared_encoder is False and loaded.config.camera_features == 32
    assert loaded.model.config.use_state is False
    assert OasisConfig.from_net_config(loaded.model.config).use_state is False
    batch = _stacked(_observation(seed=0), _observation(seed=1))
    torch.testing.assert_close(
        loaded.predict_action_chunk(batch), policy.predict_action_chunk(batch)
    )


@pytest.mark.parametrize("loss", ["nll", "manoeuvre"])
def test_forward_masks_padded_actions(loss: str) -> None:
    policy = _policy(loss=loss)
    batch = _stacked(_observation(seed=0), _observation(seed=1))
    batch["action"] = policy.predict_action_chunk(batch).clone()
    batch["action_is_pad"] = torch.tensor([[False, False, True, True]] * 2)
    fitted, info = policy.forward(batch)
    assert f"{loss}_loss" in info
    batch["action"][:, 2:] = 0.9  # wrong, but padding
    torch.testing.assert_close(policy.forward(batch)[0], fitted)
    batch["action_is_pad"][:, 2] = False
    worse, _ = policy.forward(batch)
    assert worse.item() > fitted.item() + 0.1
    per_sample, _ = policy.forward(batch, reduction="none")
    assert per_sample.shape == (2,)
    worse.backward()
    assert policy.model.encoder.convs[0].weight.grad is not None
    # The likelihood fits the distribution's scale too.
    assert id(policy.model.log_scale) in {id(parameter) for parameter in policy.get_optim_params()}


def test_the_auxiliary_loss_predicts_the_privileged_state() -> None:
    policy = _policy(aux_weight=0.5)
    assert policy.model.config.aux_outputs == len(PRIVILEGED_FIELDS)
    batch = _stacked(_observation(seed=0), _observation(seed=1))
    batch["action"] = policy.predict_action_chunk(batch).clone()
    with pytest.raises(KeyError, match=r"needs batch\['privileged_state'\].*aux_weight=0"):
        policy.forward(batch)
    batch[PRIVILEGED_KEY] = torch.rand(2, 6)  # a dataset recorded with an older state
    with pytest.raises(ValueError, match="has 6 numbers per frame, the auxiliary head predicts 10"):
        policy.forward(batch)
    batch[PRIVILEGED_KEY] = torch.rand(2, len(PRIVILEGED_FIELDS))
    loss, info = policy.forward(batch)
    expected = (policy.model.predict_aux(policy._features(batch)) - batch[PRIVILEGED_KEY]).square()
    assert info["aux_loss"] == pytest.approx(expected.mean().item(), rel=1e-5)
    assert loss.item() == pytest.approx(info["nll_loss"] + 0.5 * info["aux_loss"], rel=1e-5)
    loss.backward()
    assert policy.model.aux[0].weight.grad.abs().sum() > 0
    assert {id(p) for p in policy.model.aux.parameters()} <= {
        id(p) for p in policy.get_optim_params()
    }
    with pytest.raises(ValueError, match="aux_weight must be >= 0"):
        _config(aux_weight=-1.0)


def test_the_policy_config_is_the_networks() -> None:
    config = _config(head="tanh_normal", init_scale=(0.4, 0.2), hidden_dim=32)
    net = config.net_config()
    assert (net.head, net.init_scale, net.hidden_dim, net.frames) == (
        "tanh_normal",
        (0.4, 0.2),
        32,
        2,
    )
    assert OasisConfig.from_net_config(net).net_config() == net
    assert OasisPolicy(config).model.log_scale.shape == (4, 2)  # the unimodal head


def test_bad_features_are_named() -> None:
    with pytest.raises(ValueError, match="needs 'action' of shape \\(2,\\)"):
        _config(action_dim=8).net_config()
    with pytest.raises(ValueError, match="n_action_steps must be in"):
        OasisConfig(device="cpu", n_action_steps=5)
    expected = r"loss must be one of \('nll', 'manoeuvre'\)"
    with pytest.raises(ValueError, match=expected):
        OasisConfig(device="cpu", loss="huber")
    with pytest.raises(ValueError, match="head must be one of"):
        _config(head="gmm").net_config()


def test_the_policys_defaults_are_behaviour_clonings() -> None:
    cloning = OmegaConf.to_container(load_config("bc").policy)
    config = OasisConfig(device="cpu")
    assert set(cloning) <= {*NETWORK_FIELDS, *TRAINING_FIELDS}
    for name, value in cloning.items():
        expected = tuple(value) if isinstance(value, list) else value
        assert getattr(config, name) == expected, name
    assert config.use_state is False and config.loss == "nll"
