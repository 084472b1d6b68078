"""Exploration noise held over several chunks: how long it lives, and what PPO's ratio reads."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from oasis_torchrl.config import load_config
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.train.exploration import HeldNoise, HeldNoisePolicy
from oasis_torchrl.train.ppo import PPOTrainer

from .conftest import TINY_ENV


def test_noise_lives_hold_calls_on_average() -> None:
    noise = HeldNoise(hold=4.0, generator=torch.Generator().manual_seed(0))
    previous = noise.draw(10_000, (2,))[1].clone()
    redrawn = []
    for _ in range(20):
        current = noise.draw(10_000, (2,))[1]
        redrawn.append((current != previous).any(-1).float().mean())
        previous = current.clone()
    # a redrawn row's new normal equals its old one with probability zero
    assert torch.stack(redrawn).mean().item() == pytest.approx(0.25, abs=0.01)
    uniform = noise.draw(10_000, (2,))[0]  # held or not, each row's noise stays uniform
    assert uniform.mean().item() == pytest.approx(0.5, abs=0.01)


def test_a_hold_of_one_redraws_every_call_and_below_one_is_refused() -> None:
    noise = HeldNoise(hold=1.0)
    first = noise.draw(100, (2,))[1].clone()
    assert (noise.draw(100, (2,))[1] != first).all()
    with pytest.raises(ValueError, match="at least 1 chunk"):
        HeldNoise(hold=0.5)
    with pytest.raises(ValueError, match=r"exploration\.hold_chunks must be >= 1"):
        load_config("ppo", ["exploration.hold_chunks=0"])


def _observations(net: DrivingNet, rows: int) -> TensorDict:
    frames = torch.randint(0, 255, (rows, 2, 32, 48, 3), dtype=torch.uint8)
    cameras = {camera: frames for camera in net.config.cameras}
    return TensorDict({"frame_stack": cameras, "state": torch.zeros(rows, 2)}, [rows])


@pytest.mark.parametrize("head", ["mixture", "tanh_normal"])
def test_held_actions_carry_the_policys_log_probability(head: str) -> None:
    torch.manual_seed(0)
    net = DrivingNet(DrivingNetConfig(image_size=(32, 48), head=head))
    actor = make_actor_critic(net).policy
    policy = HeldNoisePolicy(actor, hold_chunks=1e9)
    observations = _observations(net, 6)
    with set_exploration_type(ExplorationType.RANDOM):
        first = policy(observations.clone())
        second = policy(observations.clone())
        dist = actor.get_dist(observations.clone())
    torch.testing.assert_close(first["action"], second["action"])  # the noise was held
    assert first["action"].shape == (6, 4, 2) and first["action"].abs().max() < 1
    torch.testing.assert_close(first["action_log_prob"], dist.log_prob(first["action"]))
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        deployed = policy(observations.clone())["action"]
        torch.testing.assert_close(deployed, actor(observations.clone())["action"])


def test_ppo_collects_with_held_noise(tmp_path: Path) -> None:
    overrides = [
        *TINY_ENV,
        "env.num_envs=2",
        "env.max_steps=6",
        f"output_dir={tmp_path}",
        "collector.frames_per_batch=16",
        "collector.total_frames=16",
        "optim.mini_batch_size=8",
        "eval.every=0",
        "eval.episodes=1",
        "eval.max_steps=2",
        "progress=false",
        "exploration.hold_chunks=1e9",
    ]
    trainer = PPOTrainer(load_config("ppo", overrides))
    assert isinstance(trainer.collecting_policy, HeldNoisePolicy)
    held_before = trainer.collecting_policy.noise
    result = trainer.run()
    assert result.history and held_before.normal is not None  # the collector drew through it
    assert held_before.normal.shape == (2, 4, 2)  # one noise per env row
