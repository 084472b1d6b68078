"""The frames-only motion reward: its bookkeeping on a network with fixed outputs, its weights
files and their errors, and the sanity checks of Knox et al. ("Reward (mis)design for autonomous
driving") on the shipped network in the embedded world, judged by its ground truth."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.drivers import load_driver
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.envs.driving import drive
from oasis_torchrl.models.motion import MotionNet, MotionNetConfig
from oasis_torchrl.rewards import MotionModelError, MotionReward, MotionRewardConfig
from oasis_torchrl.rewards.motion_net import load_motion_net, save_motion_weights
from oasis_torchrl.sim.config import ServerConfig

TINY = MotionNetConfig(channels=(4, 4), hidden=8)


def fixed_net(progress: float, collided_logit: float = -5.0) -> MotionNet:
    """A real network whose weights are zero and whose head biases say ``progress`` metres and
    ``collided_logit`` for any chunk."""
    net = MotionNet(TINY)
    with torch.no_grad():
        for parameter in net.parameters():
            parameter.zero_()
        net.progress_head.bias.fill_(progress)
        net.collided_head.bias.fill_(collided_logit)
    return net.eval()


def step_td(rows: int, throttle: float) -> TensorDict:
    frames = torch.full((rows, 4, 64, 96, 3), 100, dtype=torch.uint8)
    action = torch.tensor([throttle, 0.0]).expand(rows, 4, 2).clone()
    return TensorDict({("pixels", "front"): frames, "action": action}, [rows])


def test_pays_the_metres_seen_less_the_deadband_never_the_throttle() -> None:
    moving = MotionReward(fixed_net(2.0), MotionRewardConfig(deadband=0.03))
    out = moving(step_td(2, throttle=0.0))
    assert out["reward_terms", "seen_progress"].flatten().tolist() == pytest.approx([1.97] * 2)
    assert out["reward"].flatten().tolist() == pytest.approx([0.197] * 2)
    still = MotionReward(fixed_net(0.02))
    for throttle in (0.0, 0.3, 1.0):  # under the deadband: nothing, whatever the throttle
        assert still(step_td(1, throttle))["reward"].item() <= 0.0


def seen_moving(net: MotionNet, metres: float) -> MotionNet:
    """``net`` now seeing ``metres`` of progress in any chunk."""
    with torch.no_grad():
        net.progress_head.bias.fill_(metres)
    return net


def test_a_car_seen_moving_then_still_under_throttle_crashes_once_after_stuck_chunks() -> None:
    net = fixed_net(2.0)
    reward = MotionReward(net, MotionRewardConfig(stuck_chunks=2))
    assert not reward(step_td(1, throttle=1.0))["terminated"].item()  # moving: armed
    seen_moving(net, 0.0)
    first = reward(step_td(1, throttle=1.0))
    assert not first["terminated"].item() and first["reward"].item() == 0.0
    second = reward(step_td(1, throttle=1.0))
    assert second["terminated"].item() and second["reward"].item() == pytest.approx(-2.0)
    third = reward(step_td(1, throttle=1.0))
    assert third["terminated"].item() and third["reward"].item() == 0.0  # the penalty is paid once
    reward.reset(torch.tensor([True]))
    assert not reward(step_td(1, throttle=1.0))["terminated"].item()


def test_a_car_pulling_away_from_rest_is_not_stuck() -> None:
    net = fixed_net(0.0)
    reward = MotionReward(net)
    for _ in range(4):  # never seen moving yet: under throttle, still is not a crash
        assert not reward(step_td(1, throttle=1.0))["terminated"].item()
    seen_moving(net, 2.0)
    reward(step_td(1, throttle=1.0))
    seen_moving(net, 0.0)
    for _ in range(3):  # stopped with the throttle released: parked, and disarmed
        assert not reward(step_td(1, throttle=0.0))["terminated"].item()
    for _ in range(3):  # pulling away again
        assert not reward(step_td(1, throttle=1.0))["terminated"].item()


def test_the_collided_head_ends_the_episode_at_once() -> None:
    reward = MotionReward(fixed_net(0.0, collided_logit=4.0))
    out = reward(step_td(1, throttle=0.0))
    assert out["terminated"].item() and out["reward_terms", "crash"].item() == 1.0


def test_swinging_the_actions_costs_their_mean_squared_change_across_chunks() -> None:
    reward = MotionReward(fixed_net(0.0), MotionRewardConfig(swing_weight=0.5))
    steady = step_td(2, throttle=1.0)
    assert reward(steady)["reward_terms", "swing"].flatten().tolist() == [0.0, 0.0]
    swinging = step_td(2, throttle=1.0)
    swinging["action"][:, :, 1] = torch.tensor([1.0, -1.0, 1.0, -1.0])
    out = reward(swinging)  # from the last steady action: 1, then three changes of 2
    assert out["reward_terms", "swing"].flatten().tolist() == pytest.approx([13 / 4] * 2)
    assert out["reward"].flatten().tolist() == pytest.approx([-13 / 8] * 2)
    reward.reset(torch.tensor([True, False]))  # a new episode has no previous action
    again = reward(swinging)["reward_terms", "swing"].flatten().tolist()
    assert again == pytest.approx([12 / 3, 16 / 4])


def test_the_last_frame_alone_is_refused_with_the_fix() -> None:
    td = TensorDict(
        {
            ("pixels", "front"): torch.zeros(1, 64, 96, 3, dtype=torch.uint8),
            "action": torch.zeros(1, 4, 2),
        },
        [1],
    )
    with pytest.raises(ValueError, match="needs all 4 frames of each chunk"):
        MotionReward(fixed_net(0.0))(td)


def test_weights_round_trip_and_a_bad_file_names_itself(tmp_path: Path) -> None:
    path = save_motion_weights(fixed_net(1.5), tmp_path / "m.pt", {"seed": 3})
    assert MotionReward(load_motion_net(str(path)))(step_td(1, 0.0))[
        "reward"
    ].item() == pytest.approx(0.147)
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not torch")
    with pytest.raises(
        MotionModelError, match=r"bad\.pt.*retrain with 'oasis-torchrl train motion'"
    ):
        load_motion_net(str(bad))
    with pytest.raises(MotionModelError, match="missing"):
        load_motion_net(str(tmp_path / "missing.pt"))


# -- the sanity checks, on the shipped network in the embedded world ---------------------------

STEPS = 90


def drive_episodes(driver: str, seed: int, prompt: str = "urban street") -> dict[str, torch.Tensor]:
    """Four episodes of ``driver`` scored by the shipped motion reward alone (the ground truth
    judges, but ends nothing)."""
    env = OasisEnv(
        "local",
        4,
        prompt,
        server=ServerConfig(width=96, height=64, processes=0),
        expert=driver == "autopilot",
        reward=MotionReward(),
        terminate_on_collision=False,
        max_steps=STEPS,
    )
    steps: list[TensorDict] = []
    try:
        env.set_seed(seed)
        drive(
            env,
            load_driver(driver),
            lambda td: steps.append(td.get("next").exclude("pixels")),
            until=lambda: False,
            max_steps=STEPS,
            reset_finished=False,
        )
    finally:
        env.close()
    rollout = torch.stack(steps, dim=1)
    ended = rollout["terminated"].squeeze(-1)
    first_end = torch.where(ended.any(1), ended.float().argmax(1), torch.tensor(STEPS))
    within = torch.arange(STEPS).unsqueeze(0) <= first_end.unsqueeze(1)
    hit = rollout["truth", "collided"].gt(0.5).any(-1)
    return {
        "return": (rollout["reward"].squeeze(-1) * within).sum(1),
        "ended": first_end,
        "collided_at": torch.where(hit.any(1), hit.float().argmax(1), torch.tensor(STEPS)),
    }


@pytest.fixture(scope="module")
def autopilot() -> dict[str, torch.Tensor]:
    return drive_episodes("autopilot", seed=11)


@pytest.fixture(scope="module")
def full_throttle() -> dict[str, torch.Tensor]:
    return drive_episodes("constant:throttle=1.0,steering=0.0", seed=11)


def test_standing_still_earns_at_most_zero() -> None:
    still = drive_episodes("constant:throttle=0.0,steering=0.0", seed=5)
    assert (still["return"] <= 0.0).all(), still["return"]


def test_weaving_without_moving_earns_nothing() -> None:
    weaving = drive_episodes("scripted:throttle=0.0,steering=sine:1.0:8", seed=5)
    assert (weaving["return"] <= 0.0).all(), weaving["return"]


def test_a_crash_is_seen_within_two_chunks_and_scores_below_driving_safely(
    autopilot: dict[str, torch.Tensor], full_throttle: dict[str, torch.Tensor]
) -> None:
    crashed = full_throttle["collided_at"] < STEPS
    assert crashed.any(), "full throttle must crash in some of these scenes"
    late = full_throttle["ended"][crashed] - full_throttle["collided_at"][crashed]
    assert (late >= 0).all() and (late <= 2).all(), late
    assert (autopilot["collided_at"] == STEPS).all()  # the autopilot drives them safely
    assert (full_throttle["return"][crashed] < autopilot["return"][crashed]).all()


def test_the_autopilot_is_never_ended_as_a_crash(autopilot: dict[str, torch.Tensor]) -> None:
    assert (autopilot["ended"] == STEPS).all(), autopilot["ended"]
