"""Capabilities found from the endpoint: ground truth where it is sent, frames-only defaults and
clear errors elsewhere."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from oasis_torchrl.config import load_config
from oasis_torchrl.envs import make_env
from oasis_torchrl.envs.capabilities import Capabilities, probe
from oasis_torchrl.rewards import DepthCollisionReward, GroundTruthReward, MotionReward
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.train.ppo import with_capabilities


@pytest.mark.parametrize("hosted", [False, True])
def test_probe_finds_ground_truth_only_where_it_is_sent(
    server_factory: Callable[..., LocalServer], hosted: bool
) -> None:
    server = server_factory(hosted=hosted, processes=0)
    found = probe(server.endpoint, api_key=server.api_key)
    assert found == Capabilities(server.endpoint, ground_truth=not hosted)


def test_auto_settings_follow_the_endpoint_and_explicit_ones_are_refused_on_frames() -> None:
    frames = ["env.server.hosted=true", "env.server.width=48", "env.server.height=32"]
    resolved = with_capabilities(load_config("ppo", frames))
    assert (resolved.privileged_critic, resolved.loss.aux_coeff) == (False, 0.0)
    embedded = with_capabilities(load_config("ppo"))
    assert (embedded.privileged_critic, embedded.loss.aux_coeff) == (True, 1.0)

    cfg = load_config("ppo", frames)
    env = make_env(cfg.env)
    try:
        reward = env.base_env.reward_module
        assert isinstance(reward, MotionReward) and not env.base_env.ground_truth
    finally:
        env.close()
    reference = make_env(load_config("ppo", [*frames, "env.reward.kind=depth"]).env)
    try:
        assert isinstance(reference.base_env.reward_module, DepthCollisionReward)
    finally:
        reference.close()
    with pytest.raises(ValueError, match="the hosted-like embedded server does not send"):
        make_env(cfg.env, privileged=True)
    explicit = load_config("ppo", [*frames, "env.reward.kind=ground_truth"])
    with pytest.raises(ValueError, match=r"env\.reward\.kind=ground_truth needs ground truth"):
        make_env(explicit.env)
    embedded_env = make_env(load_config("ppo", frames[1:]).env)
    try:
        assert isinstance(embedded_env.base_env.reward_module.base, GroundTruthReward)
    finally:
        embedded_env.close()
