"""The privileged state: scaling, caps, and the errors for fields it cannot read."""

from __future__ import annotations

import math

import pytest
import torch

from oasis_torchrl.models.privileged import MAX_DISTANCE, PRIVILEGED_FIELDS, privileged_state


def test_distances_are_capped_and_unknown_values_read_as_zero() -> None:
    truth = {field: torch.tensor([1.0, 2.0, 3.0]) for field in PRIVILEGED_FIELDS}
    truth["lane_obstacle_distance"] = torch.tensor([math.inf, 2 * MAX_DISTANCE, math.nan])
    truth["speed"] = torch.tensor([math.nan, 10.0, 20.0])
    state = privileged_state(truth)
    lane = PRIVILEGED_FIELDS.index("lane_obstacle_distance")
    assert state[:, lane].tolist() == [1.0, 1.0, 0.0]
    assert state[:, PRIVILEGED_FIELDS.index("speed")].tolist() == [0.0, 1.0, 2.0]
    assert state.shape == (3, len(PRIVILEGED_FIELDS)) and state.dtype == torch.float32


def test_a_field_without_a_scale_or_missing_from_the_truth_is_named() -> None:
    truth = {field: torch.zeros(2) for field in PRIVILEGED_FIELDS}
    with pytest.raises(ValueError, match=r"no scale for privileged fields \['x'\]"):
        privileged_state({**truth, "x": torch.zeros(2)}, ["speed", "x"])
    del truth["lanes_left"]
    with pytest.raises(KeyError, match="needs ground truth \\['lanes_left'\\]"):
        privileged_state(truth)
