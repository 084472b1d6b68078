"""Noisy-execution autopilot demonstrations: noisy actions in the env, clean ones in the data."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from tensordict import TensorDict

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers.late_reaction import LateReactionAutopilot
from oasis_torchrl.models.privileged import MAX_DISTANCE, PRIVILEGED_FIELDS, PRIVILEGED_KEY
from oasis_torchrl.train.demonstrations import ActionNoise, NoiseProcess, record_demonstrations

from .conftest import TINY_ENV


def _record(root: Path, noise: ActionNoise) -> LeRobotDataset:
    cfg = load_config("demo", [*TINY_ENV, "env.num_envs=2", "env.max_steps=3"])
    record_demonstrations(cfg.env, root, episodes=2, seed=5, noise=noise, progress=False)
    return LeRobotDataset("local/demos", root=root, video_backend="pyav")


def _executed_vs_stored(dataset: LeRobotDataset) -> torch.Tensor:
    """|executed - stored| of each chunk's last action: the next chunk's first row holds the
    executed one as its state (the env reports the previous applied action)."""
    columns = dataset.hf_dataset.with_format("torch")[:]
    state, action = columns["observation.state"], columns["action"]
    episode = columns["episode_index"]
    rows = torch.arange(3, len(action) - 1, 4)
    same_episode = episode[rows] == episode[rows + 1]
    return (state[rows + 1] - action[rows])[same_episode].abs()


def test_noise_moves_the_car_but_not_the_labels(tmp_path: Path) -> None:
    clean = _record(tmp_path / "clean", ActionNoise(0.0, 0.0, 0.0))
    noisy = _record(tmp_path / "noisy", ActionNoise(0.3, 0.3, 0.5))
    assert clean.num_episodes == noisy.num_episodes == 2
    assert _executed_vs_stored(clean).max() == 0
    assert _executed_vs_stored(noisy).max() > 0.01
    assert noisy.hf_dataset.with_format("torch")[:]["action"].abs().max() <= 1.0


def test_noise_process_is_seeded_and_resets_rows() -> None:
    first, second = (NoiseProcess(ActionNoise(), rows=4, seed=1) for _ in range(2))
    torch.testing.assert_close(first.step(), second.step())
    first.reset(torch.tensor([False, True, False, False]))
    assert first.value[1].abs().sum() == 0 and first.value[0].abs().sum() > 0
    with pytest.raises(ValueError, match="correlation in"):
        ActionNoise(correlation=1.0)


def _truth_row(distance: float, offset: float = 0.0) -> dict[str, torch.Tensor]:
    values = {
        "lane_obstacle_distance": distance,
        "lane_offset": offset,
        "heading_error": 0.0,
        "speed": 10.0,
    }
    return {key: torch.full((1, 4), value) for key, value in values.items()}


def _late_chunk(late: LateReactionAutopilot, distance: float) -> torch.Tensor:
    expert = torch.tensor([[[0.4, -0.3]] * 4])
    td = TensorDict({"expert_action": expert, "truth": _truth_row(distance)}, batch_size=[1])
    return late(td).get("action")[0]


def test_late_reaction_keeps_its_lane_until_its_distance_then_drives_as_the_autopilot() -> None:
    late = LateReactionAutopilot(reaction=(10.0, 20.0), seed=3)
    assert _late_chunk(late, math.inf)[:, 1].abs().max() == 0  # centred: straight on
    assert _late_chunk(late, 25.0)[:, 1].abs().max() == 0  # beyond reach: still no reaction
    reaction = float(late._distances[0])
    assert 10.0 <= reaction <= 20.0
    assert _late_chunk(late, reaction + 0.5)[:, 1].abs().max() == 0  # one approach, one distance
    assert float(late._distances[0]) == reaction
    torch.testing.assert_close(_late_chunk(late, reaction - 0.5)[:, 1], torch.full((4,), -0.3))
    assert (_late_chunk(late, reaction - 0.5)[:, 0] == 0.4).all()  # the throttle is always its


def test_late_reaction_draws_each_approach_its_own_distance() -> None:
    late = LateReactionAutopilot(reaction=(5.0, 40.0), seed=0)
    draws = set()
    for _ in range(20):
        _late_chunk(late, math.inf)
        _late_chunk(late, 30.0)
        draws.add(float(late._distances[0]))
    assert len(draws) > 10 and min(draws) >= 5.0 and max(draws) <= 40.0


def test_late_reaction_errors_name_the_problem() -> None:
    with pytest.raises(ValueError, match="near <= far"):
        LateReactionAutopilot(reaction=(30.0, 10.0))
    with pytest.raises(ValueError, match=r"record.late_reaction must be \[near, far\]"):
        load_config("demo", ["record.late_reaction=[8,20,40]"])
    td = TensorDict({"expert_action": torch.zeros(1, 4, 2)}, batch_size=[1])
    with pytest.raises(KeyError, match="ground truth"):
        LateReactionAutopilot()(td)


def test_late_reaction_records_blocked_lanes_labelled_by_the_autopilot(tmp_path: Path) -> None:
    """On the embedded server: the executed car stays in its lane with an obstacle close ahead
    in it, where the stored label (the autopilot's) steers out."""
    overrides = [*TINY_ENV, "env.num_envs=2", "env.max_steps=40", "env.prompts=[urban]"]
    cfg = load_config("demo", overrides)
    learner = LateReactionAutopilot(reaction=(8.0, 8.0))
    record_demonstrations(
        cfg.env,
        tmp_path / "late",
        episodes=2,
        seed=5,
        noise=ActionNoise(0.0, 0.0, 0.0),
        learner=learner,
        progress=False,
    )
    columns = LeRobotDataset("local/late", root=tmp_path / "late").hf_dataset.with_format("torch")[
        :
    ]
    blocked = columns[PRIVILEGED_KEY][:, PRIVILEGED_FIELDS.index("lane_obstacle_distance")]
    offset = columns[PRIVILEGED_KEY][:, PRIVILEGED_FIELDS.index("lane_offset")]
    approaching = (blocked * MAX_DISTANCE > 12.0) & (blocked * MAX_DISTANCE < 30.0)
    assert approaching.sum() > 8
    assert (offset[approaching].abs() * 2.0 < 0.3).all()  # scaled by 2 m: within 0.3 m
    assert columns["action"][approaching, 1].abs().max() > 0.1
