"""Drivers of ``oasis-torchrl record``: the server's expert, scripts, saved policies."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictModule

import oasis_torchrl.drivers
from oasis_torchrl.drivers import Autopilot, PolicyDriver, ScriptedDriver, load_driver
from oasis_torchrl.drivers.folders import export_lerobot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.models import DrivingNet, DrivingNetConfig
from oasis_torchrl.models.checkpoint import save_checkpoint
from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.vehicle import VehicleParams, VehicleState, step_vehicle

ABOVE_THE_DRIVERS = (
    "oasis_torchrl.cli",
    "oasis_torchrl.commands",
    "oasis_torchrl.train",
    "oasis_torchrl.distributed",
    "oasis_torchrl.serving",
    "oasis_torchrl.config.pipeline",
)
"""The entry points, the pipelines and the main job's settings: drivers run under them."""


def test_the_drivers_import_nothing_above_them() -> None:
    folder = Path(oasis_torchrl.drivers.__file__).parent
    imported = {
        (path.name, node.module)
        for path in folder.glob("*.py")
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ImportFrom) and node.module
    }
    assert imported and not [item for item in imported if item[1].startswith(ABOVE_THE_DRIVERS)]


def test_autopilot_drives_with_the_servers_expert() -> None:
    prompts = ["urban street", "highway", "rural road"]
    env = OasisEnv(
        "local", 3, prompts, server=ServerConfig(width=64, height=48), max_steps=60, expert=True
    )
    env.set_seed(4)
    try:
        rollout = env.rollout(60, Autopilot())
    finally:
        env.close()
    assert torch.equal(rollout["action"], rollout["expert_action"])
    truth = rollout["next", "truth"]
    assert not truth["collided"].any()
    assert (truth["progress"][:, -1, -1] > 60.0).all()  # 12 s of driving in every scene


def test_autopilot_needs_the_expert_and_stops_rows_without_one() -> None:
    expert = torch.full((3, 4, 2), 0.5)
    expert[1] = float("nan")  # a row whose session was lost
    actions = Autopilot(chunk_actions=False)(TensorDict(expert_action=expert, batch_size=[3]))
    assert actions["action"].tolist() == [[0.5, 0.5], [0.0, 0.0], [0.5, 0.5]]
    with pytest.raises(KeyError, match="built with expert=True"):
        Autopilot()(TensorDict(truth=TensorDict(speed=torch.zeros(3, 4)), batch_size=[3]))


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


def test_a_weave_changes_lane_and_back_on_either_side() -> None:
    driver = ScriptedDriver.from_spec("throttle=1.0,steering=weave:0.088:20:100")
    td = TensorDict(batch_size=[2])
    steering = torch.cat([driver(td)["action"][0, :, 1] for _ in range(100)]).tolist()
    car, params, lateral = VehicleState(0.0, 0.0, 0.0, 14.0), VehicleParams(), []
    for frame, steer in enumerate(steering):
        car = step_vehicle(car, 1.0, steer, params, 0.05)
        if frame % 100 == 99:  # each S-curve done: one lane across, heading straight again
            lateral.append(car.y)
            assert car.heading == pytest.approx(0.0, abs=1e-6)
    assert lateral == pytest.approx([-3.18, 0.0, 3.18, 0.0], abs=0.05)  # + steers right
    for spec, problem in (
        ("steering=weave:0.1:20", "expected .*weave:AMPLITUDE:PULSE_FRAMES:GAP_FRAMES"),
        ("steering=weave:0.1:20:30", "2 x pulse <= gap, got 20 and 30"),
        ("steering=weave:0.1:2.5:30", "invalid literal for int"),
    ):
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


def test_one_grammar_names_every_driver(tmp_path: Path) -> None:
    net = DrivingNet(DrivingNetConfig(image_size=(32, 48)))
    checkpoint = save_checkpoint(tmp_path / "ppo.pt", net)
    folder = export_lerobot(net, tmp_path / "bc_policy")
    scripted = tmp_path / "linear.pt"
    torch.jit.save(torch.jit.script(torch.nn.Linear(2, 8)), scripted)
    assert type(load_driver("autopilot")).__name__ == "Autopilot"
    assert load_driver("constant:throttle=1").image_size is None
    assert (
        load_driver("scripted:steering=0.2")(TensorDict(batch_size=[1]))["action"][0, 0, 1] == 0.2
    )
    for saved in (checkpoint, folder):  # the driving network: deterministic, at its size
        driver = load_driver(saved)
        assert driver.image_size == (32, 48)
        frames = torch.randint(0, 255, (2, 2, 32, 48, 3), dtype=torch.uint8)
        stack = {camera: frames for camera in CAMERAS}
        observation = TensorDict(frame_stack=stack, state=torch.zeros(2, 2), batch_size=[2])
        first, second = (driver(observation.clone())["action"] for _ in range(2))
        assert torch.equal(first, second)
        bare_env = TensorDict(pixels=stack, state=torch.zeros(2, 2), batch_size=[2])
        missing = r"reads \('frame_stack', '\w+'\) \(frames one chunk apart\).*make_env"
        with pytest.raises(ValueError, match=missing):
            driver(bare_env)
    assert isinstance(load_driver(scripted, in_keys=["state"]), PolicyDriver)
    with pytest.raises(ValueError, match="is none of 'autopilot', 'scripted:<script>'"):
        load_driver("autopilt")
    with pytest.raises(ValueError, match="bad driver spec item"):
        load_driver("scripted:speed=1")
