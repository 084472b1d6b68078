"""Behaviour of the reference SDK's depth-collision reward on hand-built metric depth scenes."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.rewards import (
    DepthCollisionConfig,
    DepthCollisionReward,
    GroundTruthDepth,
)
from oasis_torchrl.rewards.depth_collision import row_quantile

HEIGHT, WIDTH = 64, 96
HORIZON = 23  # rows above are sky
STRIP_START = 58  # round(64 * 0.9)
SCORED_PIXELS = STRIP_START * WIDTH


def open_road() -> torch.Tensor:
    """Metric depth of a flat road: sky on top, depth falling to 2 m at the bottom row."""
    rows = torch.arange(HEIGHT, dtype=torch.float32).view(HEIGHT, 1).expand(HEIGHT, WIDTH)
    return torch.where(rows > HORIZON, 80.0 / (rows - HORIZON), torch.inf)


def road_with_obstacle(rows: slice, cols: slice) -> torch.Tensor:
    """The open road with a box 1.9 m away (nearer than the ego strip) over rows x cols."""
    depth = open_road().clone()
    depth[rows, cols] = 1.9
    return depth


def step_td(throttle: list[float], steering: list[float], depth: torch.Tensor | None = None):
    """A step TensorDict: one row per throttle/steering value, the same chunk value 4 times."""
    batch = len(throttle)
    action = torch.stack([torch.tensor(throttle), torch.tensor(steering)], dim=-1)
    action = action.view(batch, 1, 2).expand(batch, 4, 2)
    if depth is None:
        depth = open_road().expand(batch, HEIGHT, WIDTH)
    return TensorDict({"action": action, ("depth", "front"): depth}, batch_size=[batch])


def make_reward() -> DepthCollisionReward:
    return DepthCollisionReward(GroundTruthDepth("front"))


def test_forward_preference_full_over_half_over_zero_and_negative_is_zero() -> None:
    out = make_reward()(step_td([1.0, 0.5, 0.0, -1.0], [0.0] * 4))
    reward = out["reward"].flatten()
    assert reward[0] == pytest.approx(1.0)
    assert reward[0] > reward[1] > reward[2]
    assert reward[1] < 0.5  # convex: half throttle earns less than half
    assert reward[2] == 0.0 and reward[3] == 0.0
    assert torch.equal(out["reward_terms", "forward"], out["reward"])


def test_output_layout_matches_the_declared_terms() -> None:
    reward = make_reward()
    out = reward(step_td([1.0, 0.0], [0.0, 0.0]))
    assert out.batch_size == torch.Size([2])
    assert out["reward"].dtype == torch.float32 and out["reward"].shape == (2, 1)
    assert out["terminated"].dtype == torch.bool and out["terminated"].shape == (2, 1)
    names = {"forward", "straightness_penalty", "heading", "collision_risk", "near_fraction"}
    assert set(reward.terms) == names
    assert set(out["reward_terms"].keys()) == names
    for name in names:
        assert out["reward_terms", name].shape == (2, 1)


def test_free_play_small_steering_has_no_penalty() -> None:
    reward = make_reward()
    for _ in range(8):  # heading +1 per step up to the free play of 8
        out = reward(step_td([1.0], [0.25]))
        assert out["reward_terms", "straightness_penalty"].item() == 0.0
    assert out["reward_terms", "heading"].item() == pytest.approx(8.0)
    out = reward(step_td([1.0], [0.25]))  # one past the free play: 1/8 of the span
    assert out["reward_terms", "straightness_penalty"].item() == pytest.approx(0.1 / 8)
    assert out["reward"].item() == pytest.approx(1.0 - 0.1 / 8)


def test_clamp_penalty_saturates_and_heading_never_exceeds_16() -> None:
    reward = make_reward()
    for _ in range(10):  # +4 per step would reach 40 without the clamp
        out = reward(step_td([0.0, 0.0], [1.0, -1.0]))
    assert out["reward_terms", "heading"].flatten().tolist() == [16.0, -16.0]
    assert out["reward_terms", "straightness_penalty"].flatten().tolist() == pytest.approx(
        [0.1, 0.1]
    )
    assert out["reward"].flatten().tolist() == pytest.approx([-0.1, -0.1])


def test_balanced_swerve_returns_heading_to_zero_without_penalty() -> None:
    reward = make_reward()
    for steering in (-1.0, -1.0, -1.0):  # heading -12: penalised half-way
        out = reward(step_td([1.0], [steering]))
    assert out["reward_terms", "straightness_penalty"].item() == pytest.approx(0.05)
    for steering in (1.0, 1.0, 1.0):
        out = reward(step_td([1.0], [steering]))
    assert out["reward_terms", "heading"].item() == pytest.approx(0.0)
    assert out["reward_terms", "straightness_penalty"].item() == 0.0


def test_near_blob_over_six_percent_terminates_open_road_does_not() -> None:
    blob = (slice(30, 51), slice(30, 66))  # 21 x 36 pixels, 13.6% of the scored image
    depth = torch.stack([open_road(), road_with_obstacle(*blob)])
    out = make_reward()(step_td([1.0, 1.0], [0.0, 0.0], depth))
    assert out["terminated"].flatten().tolist() == [False, True]
    assert out["reward_terms", "collision_risk"].flatten().tolist() == [0.0, 1.0]
    near = out["reward_terms", "near_fraction"].flatten()
    assert near[0].item() == 0.0
    assert near[1].item() == pytest.approx(21 * 36 / SCORED_PIXELS)
    assert out["reward"].flatten().tolist() == pytest.approx([1.0, 1.0])  # risk only terminates


def test_small_blob_gives_proportional_risk_without_termination() -> None:
    blob = (slice(30, 37), slice(30, 66))  # 7 x 36 pixels, 4.5% of the scored image
    out = make_reward()(step_td([1.0], [0.0], road_with_obstacle(*blob).unsqueeze(0)))
    expected = 7 * 36 / SCORED_PIXELS / 0.06
    assert out["reward_terms", "collision_risk"].item() == pytest.approx(expected)
    assert not out["terminated"].item()


def test_ego_strip_itself_is_excluded_from_the_near_fraction() -> None:
    depth = road_with_obstacle(slice(STRIP_START, HEIGHT), slice(0, WIDTH)).unsqueeze(0)
    out = make_reward()(step_td([1.0], [0.0], depth))
    assert out["reward_terms", "near_fraction"].item() == 0.0
    assert not out["terminated"].item()


def test_partial_reset_zeroes_only_masked_rows() -> None:
    reward = make_reward()
    for _ in range(3):
        reward(step_td([0.0] * 3, [1.0, -1.0, 1.0]))
    reward.reset(torch.tensor([True, False, True]))
    out = reward(step_td([0.0] * 3, [0.0] * 3))
    assert out["reward_terms", "heading"].flatten().tolist() == [0.0, -12.0, 0.0]
    reward.reset(None)
    out = reward(step_td([0.0] * 3, [0.0] * 3))
    assert out["reward_terms", "heading"].flatten().tolist() == [0.0, 0.0, 0.0]


def test_reset_mask_of_wrong_size_is_rejected() -> None:
    reward = make_reward()
    reward(step_td([0.0] * 3, [1.0] * 3))
    with pytest.raises(ValueError, match=r"reset mask must be a bool tensor of shape \[3\]"):
        reward.reset(torch.tensor([True, False]))


def test_config_overrides_constants() -> None:
    config = DepthCollisionConfig(
        straightness_weight=0.3, heading_free_play=4.0, heading_clamp=12.0
    )
    reward = DepthCollisionReward(GroundTruthDepth(), config)
    for _ in range(2):
        out = reward(step_td([1.0], [1.0]))
    assert out["reward_terms", "straightness_penalty"].item() == pytest.approx(0.3 * 4 / 8)
    with pytest.raises(ValueError, match="heading_free_play"):
        DepthCollisionConfig(heading_free_play=20.0)


def test_bad_inputs_name_the_problem() -> None:
    reward = make_reward()
    td = step_td([1.0], [0.0])
    with pytest.raises(KeyError, match="action"):
        reward(td.exclude("action"))
    td["action"] = torch.zeros(1, 4, 3)
    with pytest.raises(ValueError, match=r"td\['action'\] as \[1, T, 2\]"):
        reward(td)


def test_row_quantile_matches_torch_quantile() -> None:
    values = torch.rand(4, 577)
    for q in (0.0, 0.5, 0.95, 1.0):
        assert torch.allclose(row_quantile(values, q), torch.quantile(values, q, dim=1))
