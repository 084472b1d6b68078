"""Drivers of ``oasis-torchrl record``: autopilot from TensorDicts, scripts, saved policies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import NonTensorStack, TensorDict
from tensordict.nn import TensorDictModule

from oasis_torchrl.client import TRUTH_FIELDS
from oasis_torchrl.drivers import Autopilot, PolicyDriver, ScriptedDriver, cached_scene
from oasis_torchrl.sim.world import World

WORLDS = [("urban street", 4), ("highway", 1), ("rural road", 2), ("city at night", 0)]


def _observation(worlds: list[World], chunks: list[list]) -> TensorDict:
    """The env's observation keys for these worlds: truth of each chunk, prompt, seed."""
    truth = {
        name: torch.tensor([[float(getattr(t, name)) for t in chunk] for chunk in chunks])
        for name in TRUTH_FIELDS
    }
    return TensorDict(
        truth=truth,
        prompt=NonTensorStack(*(prompt for prompt, _ in WORLDS)),
        episode_seed=torch.tensor([[seed] for _, seed in WORLDS]),
        batch_size=[len(worlds)],
    )


def test_autopilot_drives_from_the_tensordict_alone() -> None:
    worlds = [World(cached_scene(prompt, seed), dt=0.05) for prompt, seed in WORLDS]
    chunks = [[world.advance(0.0, 0.0) for _ in range(4)] for world in worlds]  # the reset
    autopilot = Autopilot()
    for _ in range(100):  # 20 s of driving
        actions = autopilot(_observation(worlds, chunks))["action"]
        assert actions.shape == (len(worlds), 4, 2)
        chunks = [
            [world.advance(*actions[row, k].tolist()) for k in range(4)]
            for row, world in enumerate(worlds)
        ]
    for world in worlds:
        assert not world.truth.collided and world.truth.progress > 120.0, world.truth


def test_autopilot_needs_ground_truth_and_skips_rows_without_it() -> None:
    worlds = [World(cached_scene(prompt, seed), dt=0.05) for prompt, seed in WORLDS]
    td = _observation(worlds, [[world.truth] * 4 for world in worlds])
    td["truth", "speed"][1] = float("nan")  # a row whose session was lost
    actions = Autopilot(chunk_actions=False)(td)["action"]
    assert actions.shape == (4, 2) and actions[1].tolist() == [0.0, 0.0] and actions[0, 0] > 0
    del td["truth"]
    with pytest.raises(KeyError, match="embedded server"):
        Autopilot()(td)


def test_scripted_driver_follows_its_spec() -> None:
    driver = ScriptedDriver.from_spec("throttle=-0.2, steering=sine:0.5:8:0.1")
    td = TensorDict(batch_size=[3])
    first, second = driver(td)["action"].clone(), driver(td)["action"]
    frames = np.arange(8)
    expected = 0.1 + 0.5 * np.sin(2 * np.pi * frames / 8)
    np.testing.assert_allclose(torch.cat([first[0], second[0]])[:, 1], expected, atol=1e-6)
    assert (first[..., 0] == -0.2).all() and first.shape == (3, 4, 2)
    for spec, problem in (("speed=1", "speed=1"), ("steering=sine:1", "sine:AMPLITUDE")):
        with pytest.raises(ValueError, match=problem):
            ScriptedDriver.from_spec(spec)


def _observation_with_pixels(rows: int) -> TensorDict:
    pixels = {
        c: torch.full((rows, 6, 8, 3), 200, dtype=torch.uint8) for c in ("front", "left_forward")
    }
    return TensorDict(pixels=pixels, state=torch.zeros(rows, 2), batch_size=[rows])


class _MeanBrightness(torch.nn.Module):
    def forward(self, left: torch.Tensor, front: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        level = (left.float().mean((1, 2, 3)) + front.float().mean((1, 2, 3))) / 510.0
        return torch.stack([level, state[:, 1] - 2.0], dim=-1)


def test_saved_policies_drive(tmp_path: Path) -> None:
    scripted = tmp_path / "policy.pt"
    torch.jit.save(torch.jit.script(_MeanBrightness()), scripted)
    action = PolicyDriver.load(scripted)(_observation_with_pixels(2))["action"]
    assert action.shape == (2, 4, 2)
    assert action[0, 0].tolist() == pytest.approx([200 / 255, -1.0])  # clamped to [-1, 1]

    pickled = tmp_path / "module.pt"
    module = TensorDictModule(torch.nn.Linear(2, 8), in_keys=["state"], out_keys=["action"])
    torch.save(module, pickled)
    assert PolicyDriver.load(pickled)(_observation_with_pixels(3))["action"].shape == (3, 4, 2)

    wrong = PolicyDriver(torch.nn.Linear(2, 3), in_keys=["state"])
    with pytest.raises(ValueError, match=r"policy action must be .* got \[2, 3\]"):
        wrong(_observation_with_pixels(2))
    with pytest.raises(FileNotFoundError):
        PolicyDriver.load(tmp_path / "missing.pt")


def test_record_command_offers_every_driver_kind() -> None:
    from oasis_torchrl.config.recording import DRIVERS
    from oasis_torchrl.drivers import DRIVER_KINDS

    assert DRIVERS == DRIVER_KINDS
