"""What a clone needs to know: behaviour cloning of the autopilot from privileged state vectors.

The camera clones learn, beside the actions, to predict the simulator's privileged state (the
auxiliary loss), and PPO's critic reads it. Which numbers that state holds decides what the
encoder is taught to see. This script asks how far a clone gets that is handed such a state
exactly, with no perception at all: if even it cannot imitate the autopilot, the state leaves out
what the autopilot decides on.

Every run records autopilot demonstrations on the main job's training scenes
(``TRAINING_PROMPTS``) with the physics alone (no frames rendered), each executed action with
Gaussian noise so the demonstrations show recoveries, and fits one MLP per state set and seed to
the autopilot's chunk of 4 actions (L1 loss, as a unimodal clone). The clones then drive the
learning benchmark's evaluation (urban, 32 episodes on seed 1000, up to 150 chunks) beside the
autopilot on the same episodes; the figure is the mean distance before a collision. State sets:

- ``car_centred``: the privileged state before this script (speed, lateral offset, heading
  error, obstacle distance in the car's path, in strips one lane width left and right of the car);
- ``lane_centred``: :data:`~oasis_torchrl.models.privileged.PRIVILEGED_FIELDS` (the offset in the
  car's lane, the lanes on each side, obstacle distances in the car's lane and the lanes beside).

With ``--camera-clone POLICY`` (a camera clone with its auxiliary head: a BC policy folder of
the main job or the learning benchmark, e.g. ``bc/round_2/policy``), the lane-centred clones also
drive on the state that camera clone's auxiliary head reads from the cameras, on the embedded
server, beside the camera clone itself: how well the cameras tell the clone what it needs.

Usage: ``python benchmarks/state_clone.py [--demos 64 --seeds 0 1 --camera-clone POLICY]``;
prints JSON (about 10 min on 2 cores, and 3 min per run with a camera clone).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import asdict

import numpy as np
import torch
from omegaconf import OmegaConf
from torch import nn
from tqdm import tqdm

from oasis_torchrl.config import load_config
from oasis_torchrl.config.pipeline import TRAINING_PROMPTS
from oasis_torchrl.drivers.folders import load_net
from oasis_torchrl.drivers.policy import PolicyDriver
from oasis_torchrl.envs.episodes import EpisodePlanner
from oasis_torchrl.models import DrivingNet, observation_spec
from oasis_torchrl.models.actor_critic import observation_keys
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, privileged_state
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.simulator import Simulator
from oasis_torchrl.sim.world import FrameTruth
from oasis_torchrl.train.evaluate import Evaluator

STATE_SETS = {
    "car_centred": (
        "speed",
        "lateral_offset",
        "heading_error",
        "obstacle_distance",
        "obstacle_distance_left",
        "obstacle_distance_right",
    ),
    "lane_centred": PRIVILEGED_FIELDS,
}


def state_of(truth: FrameTruth, fields: Sequence[str]) -> torch.Tensor:
    """``[len(fields)]``: the scaled privileged state of one frame's truth."""
    values = {name: torch.tensor(float(value)) for name, value in asdict(truth).items()}
    return privileged_state(values, fields)


def record(
    episodes: int, max_steps: int, noise: float, seed: int
) -> list[tuple[FrameTruth, np.ndarray]]:
    """Autopilot drives on the training scenes: the truth at every chunk start and the chunk the
    autopilot chose there; the executed chunk carries Gaussian noise (std ``noise``)."""
    rng = np.random.default_rng(seed)
    simulator = Simulator(96, 64)
    rows = []
    for episode in tqdm(range(episodes), desc="demonstrations", unit="episode"):
        simulator.reset(TRAINING_PROMPTS[episode % len(TRAINING_PROMPTS)], int(rng.integers(2**62)))
        pilot = Autopilot(simulator)
        for _ in range(max_steps):
            truth, chunk = simulator.truth, pilot.act()
            rows.append((truth, chunk))
            executed = np.clip(chunk + noise * rng.standard_normal(chunk.shape), -1.0, 1.0)
            if simulator.step(executed.astype(np.float32), render=False).truth[-1].collided:
                break
    return rows


def fit(
    rows: list[tuple[FrameTruth, np.ndarray]], fields: Sequence[str], steps: int, seed: int
) -> nn.Module:
    """An MLP from the state to the chunk (tanh-bounded), fitted with L1 on minibatches of 256."""
    torch.manual_seed(seed)
    states = torch.stack([state_of(truth, fields) for truth, _ in rows])
    chunks = torch.tensor(np.stack([chunk.reshape(-1) for _, chunk in rows]))
    net = nn.Sequential(
        nn.Linear(len(fields), 256),
        nn.ReLU(),
        nn.Linear(256, 256),
        nn.ReLU(),
        nn.Linear(256, chunks.shape[1]),
        nn.Tanh(),
    )
    optimiser = torch.optim.Adam(net.parameters(), lr=1e-3)
    for _ in range(steps):
        batch = torch.randint(0, len(states), (256,))
        loss = (net(states[batch]) - chunks[batch]).abs().mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    return net.eval()


def drive(
    driver: nn.Module | None, fields: Sequence[str], prompt: str, seed: int, max_steps: int
) -> tuple[float, bool]:
    """Distance and collision of one episode of a clone (``None``: the autopilot)."""
    simulator = Simulator(96, 64)
    simulator.reset(prompt, seed)
    pilot = Autopilot(simulator)
    for _ in range(max_steps):
        chunk = pilot.act()
        if driver is not None:
            with torch.no_grad():
                chunk = driver(state_of(simulator.truth, fields)[None])[0].reshape(-1, 2).numpy()
        truth = simulator.step(chunk.astype(np.float32), render=False).truth[-1]
        if truth.collided:
            return truth.distance, True
    return simulator.truth.distance, False


def evaluation_episodes(prompt: str, seed: int, episodes: int) -> tuple[list[str], list[int]]:
    """The prompts and seeds of an evaluation's episodes on ``prompt``, one per env row, as the
    env seeds them from ``seed``."""
    planner = EpisodePlanner(prompt, num_rows=episodes)
    planner.set_seed(seed)
    return planner.next_episodes(range(episodes))


def evaluate(
    driver: nn.Module | None, fields: Sequence[str], args: argparse.Namespace
) -> dict[str, float]:
    """Mean distance and collision rate on the evaluation's episodes (the env's own seeding)."""
    prompts, seeds = evaluation_episodes(args.eval_prompt, args.eval_seed, args.episodes)
    results = [
        drive(driver, fields, prompt, seed, args.max_steps)
        for prompt, seed in zip(prompts, seeds, strict=True)
    ]
    return {
        "mean_distance": float(np.mean([distance for distance, _ in results])),
        "collision_rate": float(np.mean([hit for _, hit in results])),
    }


class PredictedStateDriver(nn.Module):
    """A state clone that reads the state a camera network's auxiliary head predicts."""

    def __init__(self, net: DrivingNet, state_clone: nn.Module) -> None:
        super().__init__()
        self.net, self.state_clone = net, state_clone

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        *images, state = inputs
        predicted = self.net.predict_aux(self.net.features(images, state))
        return self.state_clone(predicted).reshape(len(state), -1, 2)


def evaluate_on_cameras(drivers: dict[str, PolicyDriver], args: argparse.Namespace) -> dict:
    """Mean distance and collision rate of each driver on the embedded server, on the same
    episodes as :func:`evaluate`."""
    scenes = {
        "prompts": [args.eval_prompt],
        "episodes": args.episodes,
        "seeds": [args.eval_seed],
        "max_steps": args.max_steps,
    }
    cfg = OmegaConf.merge(load_config("demo", ["progress=false"]), {"eval": scenes})
    results = {}
    for name, driver in drivers.items():
        with Evaluator.for_driver(cfg.env, cfg.eval, driver) as evaluator:
            report = evaluator.evaluate(driver)
        results[name] = {
            "mean_distance": report.mean_distance,
            "collision_rate": report.collision_rate,
        }
    return results


def load_camera_clone(path: str) -> DrivingNet:
    """The camera clone at ``path``, in eval mode, after checking it has an auxiliary head for
    the privileged fields."""
    net = load_net(path).eval()
    if net.config.aux_outputs != len(PRIVILEGED_FIELDS):
        raise ValueError(
            f"{path} has no auxiliary head for the {len(PRIVILEGED_FIELDS)} privileged fields "
            f"(aux_outputs={net.config.aux_outputs}): train it with policy.aux_weight > 0"
        )
    return net


def camera_drivers(path: str, state_clone: nn.Module) -> dict[str, PolicyDriver]:
    """The camera clone at ``path`` and ``state_clone`` on its predicted state."""
    net = load_camera_clone(path)
    predicted = PolicyDriver(
        PredictedStateDriver(net, state_clone),
        in_keys=observation_keys(net),
        image_size=tuple(net.config.image_size),
        frame_stack=net.config.frames,
        observation_spec=observation_spec(net),
    )
    return {"camera_clone": PolicyDriver.of_network(net), "on_predicted_state": predicted}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demos", type=int, default=64, help="demonstration episodes")
    parser.add_argument("--noise", type=float, default=0.05, help="executed-action noise std")
    parser.add_argument("--steps", type=int, default=4000, help="training steps per clone")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="one run per seed")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--eval-seed", type=int, default=1000)
    parser.add_argument("--eval-prompt", default="urban")
    parser.add_argument("--max-steps", type=int, default=150, help="chunks per episode")
    parser.add_argument("--camera-clone", help="a camera clone's policy folder (see above)")
    args = parser.parse_args()

    autopilot = evaluate(None, (), args)
    report: dict[str, object] = {"settings": vars(args), "autopilot": autopilot}
    for seed in args.seeds:
        rows = record(args.demos, args.max_steps, args.noise, seed)
        for name, fields in STATE_SETS.items():
            clone = fit(rows, fields, args.steps, seed)
            result = evaluate(clone, fields, args)
            result["vs_autopilot"] = result["mean_distance"] / autopilot["mean_distance"]
            if args.camera_clone and fields == PRIVILEGED_FIELDS:
                drivers = camera_drivers(args.camera_clone, clone)
                result["cameras"] = evaluate_on_cameras(drivers, args)
            report.setdefault(name, {"fields": list(fields), "runs": []})["runs"].append(
                {"seed": seed, **result}
            )
    for name in STATE_SETS:
        runs = report[name]["runs"]
        report[name]["mean_vs_autopilot"] = float(np.mean([run["vs_autopilot"] for run in runs]))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
