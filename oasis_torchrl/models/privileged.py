"""The simulator's privileged state as the networks' training-only heads read it: the critic's
extra inputs (an asymmetric actor-critic) and the auxiliary head's targets (PPO's and behaviour
cloning's), one definition for the env transform and the datasets.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch

PRIVILEGED_FIELDS = (
    "speed",
    "lateral_offset",
    "heading_error",
    "lane_offset",
    "lanes_left",
    "lanes_right",
    "obstacle_distance",
    "lane_obstacle_distance",
    "lane_obstacle_distance_left",
    "lane_obstacle_distance_right",
)
"""Ground-truth fields of the privileged state, in order: how the car moves, where it is in its
lane and on the road, and the obstacles ahead in its path and in its lane and the lanes beside.

The distances are lane-centred (the car-centred strips ``obstacle_distance_left`` / ``_right``
are left out): a clone of the autopilot fed these ten numbers drives much farther than one fed
the car-centred six it had before (docs/experiments/2026-11-25-state-clone.md)."""
PRIVILEGED_KEY = "privileged_state"
"""The dataset column that stores it (not an ``observation.*`` key, so no policy reads it as an
input: LeRobot's policies skip it, the oasis policy learns to predict it)."""
MAX_DISTANCE = 60.0
_SCALES = {
    "speed": 10.0,
    "lateral_offset": 4.0,
    "heading_error": 1.0,
    "lane_offset": 2.0,
    "lanes_left": 1.0,
    "lanes_right": 1.0,
}
"""Rough magnitudes of the fields that are not obstacle distances: m/s, m, rad, m, lanes. The
distances are capped at 60 m, as where no obstacle is (the critic and the auxiliary head need to
know which lane is open), and scaled by it."""


def privileged_state(
    truth: Mapping[str, torch.Tensor], fields: Sequence[str] = PRIVILEGED_FIELDS
) -> torch.Tensor:
    """``[..., len(fields)]`` float32: the ``fields`` of ``truth`` (each ``[...]``; by default
    the :data:`PRIVILEGED_FIELDS`) scaled to about unit size; no obstacle (an infinite distance)
    reads as 60 m, unknown (NaN) as 0.

    Example:
        >>> truth = {field: torch.tensor([2.0, 30.0]) for field in PRIVILEGED_FIELDS}
        >>> truth["lane_obstacle_distance_left"][1] = float("inf")
        >>> privileged_state(truth)[1].tolist()
        [3.0, 7.5, 30.0, 15.0, 30.0, 30.0, 0.5, 0.5, 1.0, 0.5]
        >>> privileged_state(truth, ["speed", "lane_obstacle_distance_left"]).tolist()
        [[0.20000000298023224, 0.03333333507180214], [3.0, 1.0]]
    """
    unscaled = [f for f in fields if f not in _SCALES and "obstacle_distance" not in f]
    if unscaled:
        raise ValueError(f"no scale for privileged fields {unscaled}; known: {sorted(_SCALES)}")
    missing = [field for field in fields if field not in truth]
    if missing:
        raise KeyError(f"the privileged state needs ground truth {missing}")
    columns = []
    for field in fields:
        value = truth[field].to(torch.float32)
        if field in _SCALES:
            columns.append(value / _SCALES[field])
        else:
            distance = value.nan_to_num(0.0, posinf=MAX_DISTANCE).clamp(max=MAX_DISTANCE)
            columns.append(distance / MAX_DISTANCE)
    return torch.stack(columns, dim=-1).nan_to_num(0.0)
