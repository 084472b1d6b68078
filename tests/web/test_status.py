"""What the page shows needs no ground truth: on a world that sends none (the hosted service),
speed, progress and risk are unknown, and everything else is there."""

from __future__ import annotations

import torch
from tensordict import TensorDict

from oasis_torchrl.web.session import DriveSession
from oasis_torchrl.web.takeover import Pilot


def _session() -> DriveSession:
    return DriveSession(lambda: None, Pilot(), lambda message: None)


def test_a_world_without_ground_truth_shows_unknowns() -> None:
    frames_only = TensorDict({"next": {"reward": torch.zeros(1, 1)}}, batch_size=[1])
    status = _session().status(frames_only)
    assert status["speed"] is status["progress"] is status["risk"] is None
    assert status["chunk"] == status["late"] == 0 and status["period_ms"] == 200
    nan = torch.full((1, 4), float("nan"))
    no_truth = TensorDict({"next": {"truth": {"speed": nan, "progress": nan}}}, batch_size=[1])
    assert _session().status(no_truth)["speed"] is None  # NaN: what the env gives without truth


def test_known_truth_and_risk_show_their_last_frame() -> None:
    step = TensorDict(
        {
            "next": {
                "truth": {
                    "speed": torch.tensor([[1.0, 2.0, 3.0, 4.5]]),
                    "progress": torch.ones(1, 4),
                },
                "reward_terms": {"collision_risk": torch.tensor([[0.25]])},
            }
        },
        batch_size=[1],
    )
    status = _session().status(step)
    assert (status["speed"], status["progress"], status["risk"]) == (4.5, 1.0, 0.25)
