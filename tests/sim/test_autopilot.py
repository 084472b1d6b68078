"""The privileged autopilot drives without crashing, changes lanes, and stops when blocked."""

from __future__ import annotations

import numpy as np
import pytest

from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.scene import obstacles_at
from oasis_torchrl.sim.simulator import Simulator


def run(simulator: Simulator, distance: float, max_steps: int = 400) -> None:
    pilot = Autopilot(simulator)
    for _ in range(max_steps):
        simulator.step(pilot.act(), render=False)
        if simulator.truth.collided or simulator.truth.progress >= distance:
            return


@pytest.mark.parametrize(("prompt", "seed"), [("urban", 1), ("highway", 2), ("rural night", 3)])
def test_drives_300_m_without_collision(prompt: str, seed: int) -> None:
    simulator = Simulator(64, 48)
    simulator.reset(prompt, seed)
    run(simulator, 300.0)
    assert not simulator.truth.collided
    assert simulator.truth.progress >= 300.0


def test_changes_lane_around_a_blocked_lane_and_stops_when_all_are_blocked() -> None:
    simulator = Simulator(64, 48)
    simulator.reset("rural", 0)
    base = simulator.scene
    right, left = base.style.lane_offset(0), base.style.lane_offset(1)
    simulator.load_scene(base.with_obstacles(obstacles_at(base.road, ["car"], [80.0], [right])))
    run(simulator, 150.0)
    assert not simulator.truth.collided and simulator.truth.progress >= 150.0

    walled = base.with_obstacles(obstacles_at(base.road, ["car", "car"], [80.0] * 2, [right, left]))
    simulator.load_scene(walled)
    run(simulator, 150.0, max_steps=120)
    truth = simulator.truth
    assert not truth.collided and truth.speed == pytest.approx(0.0, abs=0.05)
    assert 0.5 < truth.obstacle_distance < 10.0


def test_recovers_from_perturbed_steering_without_stalling() -> None:
    """Demonstrations inject noise into the executed actions (DART): the autopilot must steer
    back and keep going, not brake to a stop beside an obstacle it was pushed towards (a
    stopped car cannot steer back into its lane) nor drift into one."""
    rng = np.random.default_rng(0)
    simulator = Simulator(64, 48)
    for seed in range(1000, 1006):
        simulator.reset("urban", seed)
        pilot, noise = Autopilot(simulator), np.zeros(2)
        for _ in range(150):
            noise = 0.8 * noise + rng.normal(size=2) * [0.1, 0.02]
            simulator.step(np.clip(pilot.act() + noise, -1.0, 1.0), render=False)
        assert not simulator.truth.collided, f"seed {seed}"
        assert simulator.truth.progress > 250.0, f"seed {seed}"
