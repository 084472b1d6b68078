"""The simulator's privileged state as the networks' training-only heads read it: the critic's
extra inputs (an asymmetric actor-critic) and the auxiliary head's targets (PPO's and behaviour
cloning's), one definition for the env transform and the datasets.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

PRIVILEGED_FIELDS = (
    "speed",
    "lateral_offset",
    "heading_error",
    "obstacle_distance",
    "obstacle_distance_left",
    "obstacle_distance_right",
)
"""Ground-truth fields of the privileged state, in order."""
PRIVILEGED_KEY = "privileged_state"
"""The dataset column that stores it (not an ``observation.*`` key, so no policy reads it as an
input: LeRobot's policies skip it, the oasis policy learns to predict it)."""
MAX_DISTANCE = 60.0
_SCALE = torch.tensor([10.0, 4.0, 1.0, MAX_DISTANCE, MAX_DISTANCE, MAX_DISTANCE])
"""Rough magnitudes: m/s, m, rad, then metres (the obstacle distances are capped at 60 m, as
where no obstacle is: the critic and the auxiliary head need to know which lane is open)."""
_FIRST_DISTANCE = PRIVILEGED_FIELDS.index("obstacle_distance")


def privileged_state(truth: Mapping[str, torch.Tensor]) -> torch.Tensor:
    """``[..., 6]`` float32: the :data:`PRIVILEGED_FIELDS` of ``truth`` (each ``[...]``) scaled
    to about unit size; no obstacle (an infinite distance) reads as 60 m, unknown (NaN) as 0.

    Example:
        >>> truth = {field: torch.tensor([2.0, 30.0]) for field in PRIVILEGED_FIELDS}
        >>> truth["obstacle_distance_left"][1] = float("inf")
        >>> privileged_state(truth)[1].tolist()
        [3.0, 7.5, 30.0, 0.5, 1.0, 0.5]
    """
    missing = [field for field in PRIVILEGED_FIELDS if field not in truth]
    if missing:
        raise KeyError(f"the privileged state needs ground truth {missing}")
    raw = torch.stack([truth[field].to(torch.float32) for field in PRIVILEGED_FIELDS], dim=-1)
    distances = raw[..., _FIRST_DISTANCE:].nan_to_num(0.0, posinf=MAX_DISTANCE)
    raw = torch.cat([raw[..., :_FIRST_DISTANCE], distances.clamp(max=MAX_DISTANCE)], dim=-1)
    return (raw / _SCALE.to(raw.device)).nan_to_num(0.0)
