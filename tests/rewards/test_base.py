"""The reward-module protocol adapter and output layout."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.rewards import GroundTruthReward, RewardModule, as_reward_module


def action_td(batch: int = 3) -> TensorDict:
    return TensorDict({"action": torch.rand(batch, 4, 2)}, batch_size=[batch])


@pytest.mark.parametrize("keepdim", [False, True])
def test_callable_becomes_a_reward_module(keepdim: bool) -> None:
    module = as_reward_module(lambda td: td["action"][..., 0].mean(-1, keepdim=keepdim))
    assert isinstance(module, RewardModule)
    assert module.terms == ()
    td = action_td()
    out = module(td)
    assert out.batch_size == torch.Size([3])
    assert out["reward"].shape == (3, 1) and out["reward"].dtype == torch.float32
    assert torch.allclose(out["reward"].flatten(), td["action"][..., 0].mean(-1))
    module.reset(torch.tensor([True, False, True]))


def test_reward_modules_pass_through_unwrapped() -> None:
    module = GroundTruthReward()
    assert as_reward_module(module) is module


def test_callable_results_are_checked() -> None:
    with pytest.raises(ValueError, match=r"shape \[3\] or \[3, 1\], got \[3, 4\]"):
        as_reward_module(lambda td: td["action"][..., 0])(action_td())
    with pytest.raises(TypeError, match=r"must return a torch\.Tensor, got float"):
        as_reward_module(lambda td: 1.0)(action_td())
    with pytest.raises(TypeError, match="fn must be callable"):
        as_reward_module(42)  # type: ignore[arg-type]
