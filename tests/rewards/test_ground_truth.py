"""The ground-truth reward: progress gained, a one-off collision penalty, per-row reset."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.rewards import GroundTruthReward


def truth_td(
    progress: list[list[float]],
    collided: list[list[float]] | None = None,
    lane_offset: list[list[float]] | None = None,
    lateral_offset: list[list[float]] | None = None,
) -> TensorDict:
    """A step TensorDict with ``("truth", field)`` [N, 4] for the fields the reward reads."""
    progress_t = torch.tensor(progress)
    fields = {
        "progress": progress_t,
        "collided": torch.tensor(collided) if collided else torch.zeros_like(progress_t),
        "lane_offset": torch.tensor(lane_offset) if lane_offset else torch.zeros_like(progress_t),
        "lateral_offset": (
            torch.tensor(lateral_offset) if lateral_offset else torch.zeros_like(progress_t)
        ),
    }
    return TensorDict({("truth", k): v for k, v in fields.items()}, batch_size=[len(progress)])


def test_reward_is_scaled_progress_gained_since_the_previous_step() -> None:
    reward = GroundTruthReward(progress_scale=0.1)
    first = reward(truth_td([[0.5, 1.0, 1.5, 2.0], [0.0, 0.0, 0.0, 0.0]]))
    assert first["reward_terms", "progress_gained"].flatten().tolist() == [2.0, 0.0]
    assert first["reward"].flatten().tolist() == pytest.approx([0.2, 0.0])
    second = reward(truth_td([[2.5, 3.0, 3.5, 5.0], [-0.2, -0.4, -0.6, -1.0]]))
    assert second["reward_terms", "progress_gained"].flatten().tolist() == [3.0, -1.0]
    assert second["reward"].flatten().tolist() == pytest.approx([0.3, -0.1])
    assert not second["terminated"].any()
    assert set(second["reward_terms"].keys()) == set(reward.terms)


def test_collision_penalty_is_paid_once_and_terminates_every_time() -> None:
    reward = GroundTruthReward(progress_scale=0.1, collision_penalty=10.0)
    hit = reward(truth_td([[1.0, 2.0, 2.0, 2.0]], collided=[[0, 1, 1, 1]]))
    assert hit["reward_terms", "collision"].item() == 1.0
    assert hit["reward"].item() == pytest.approx(0.2 - 10.0)
    assert hit["terminated"].item()
    again = reward(truth_td([[2.0] * 4], collided=[[1, 1, 1, 1]]))
    assert again["reward_terms", "collision"].item() == 0.0
    assert again["reward"].item() == 0.0
    assert again["terminated"].item()


def test_lane_term_is_mean_absolute_offset_from_the_lane_centre() -> None:
    reward = GroundTruthReward(progress_scale=0.0, lane_penalty=0.5)
    out = reward(truth_td([[0.0] * 4], lane_offset=[[1.0, -1.0, 2.0, -2.0]]))
    assert out["reward_terms", "lane_offset"].item() == pytest.approx(1.5)
    assert out["reward"].item() == pytest.approx(-0.75)


def test_riding_the_line_between_two_lanes_costs_and_a_lane_centre_does_not() -> None:
    reward = GroundTruthReward(progress_scale=0.0, lane_penalty=0.01)
    # A two-lane road: its centreline is the line between the lanes (half a lane, 1.6 m, from
    # each lane's centre).
    on_the_line = truth_td([[0.0] * 4], lane_offset=[[1.6] * 4], lateral_offset=[[0.0] * 4])
    in_a_lane = truth_td([[0.0] * 4], lane_offset=[[0.0] * 4], lateral_offset=[[1.6] * 4])
    assert reward(on_the_line)["reward"].item() == pytest.approx(-0.016)
    reward.reset()
    assert reward(in_a_lane)["reward"].item() == 0.0


def test_reset_restarts_only_the_masked_rows() -> None:
    reward = GroundTruthReward(progress_scale=1.0, collision_penalty=10.0, lane_penalty=0.0)
    reward(truth_td([[5.0] * 4, [5.0] * 4], collided=[[0, 0, 0, 1], [0, 0, 0, 1]]))
    reward.reset(torch.tensor([True, False]))
    # Row 0 re-prompted: progress restarts from 0, and a new collision is penalised again.
    out = reward(truth_td([[0.5, 1.0, 1.5, 2.0], [5.5, 6.0, 6.5, 7.0]], [[0, 0, 0, 1]] * 2))
    assert out["reward_terms", "progress_gained"].flatten().tolist() == [2.0, 2.0]
    assert out["reward_terms", "collision"].flatten().tolist() == [1.0, 0.0]
    assert out["reward"].flatten().tolist() == pytest.approx([-8.0, 2.0])
    reward.reset()
    out = reward(truth_td([[1.0] * 4, [1.0] * 4]))
    assert out["reward_terms", "progress_gained"].flatten().tolist() == [1.0, 1.0]


def test_missing_or_malformed_truth_is_named() -> None:
    td = truth_td([[0.0] * 4])
    with pytest.raises(KeyError, match="embedded server"):
        GroundTruthReward()(td.exclude(("truth", "collided")))
    td["truth", "progress"] = torch.zeros(1, 4, 1)
    with pytest.raises(ValueError, match=r"\('truth', 'progress'\)\] as \[1, T\]"):
        GroundTruthReward()(td)


def test_batch_size_change_without_full_reset_is_rejected() -> None:
    reward = GroundTruthReward()
    reward(truth_td([[0.0] * 4, [0.0] * 4]))
    with pytest.raises(ValueError, match="holds 2 rows but td has 1"):
        reward(truth_td([[0.0] * 4]))
