"""How much data the cameras need: the clone's encoder fitted to the privileged state, by data size.

``perception.py`` found that the camera clones read the obstacle in their lane at R^2 0.2-0.3, and
``state_clone.py`` that the true state is all a clone needs. This script asks whether the encoder
or the data limits that: it fits the clones' encoder (:class:`MultiCameraEncoder` with the
:class:`DrivingNetConfig` defaults: two frames one chunk apart, three cameras at 64x96) with a small
head to the privileged state (:data:`PRIVILEGED_FIELDS`, MSE), on training sets of different sizes,
with and without mirror augmentation (:class:`~oasis_torchrl.train.mirror.Mirror`), and reports
each field's R^2 on held-out drives (urban, seeds no training drive uses).

The drives are rendered in-process by the embedded server's simulator at 96x64 (the frames the
server would encode, without the video round trip): the autopilot drives the main job's training
scenes with Gaussian noise on every executed action, and in every other episode the car keeps its
lane (``lane_keeping``) until the obstacle in it is nearer than a distance drawn per approach, as
``record.late_reaction`` demonstrations do, so the states include obstacles close ahead.
Every run sees the same number of samples (``--steps`` x 64); the baseline is the smallest
training set without mirroring, in the same run.

Usage: ``python benchmarks/perception_data.py [--episodes 320 --sizes 9600 0 --steps 6000]``
(size 0: every training row); prints JSON (about 20 min on 2 cores). With ``--ppo-checkpoint
PATH`` it fits a fresh PPO network's encoder and auxiliary head on every training row instead and
saves it for PPO's ``init_from``: PPO from an encoder that already sees (about 10 min).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass

import numpy as np
import torch
from perception import explained_variance
from torch import nn
from tqdm import tqdm

from oasis_torchrl.config import load_config
from oasis_torchrl.config.pipeline import TRAINING_PROMPTS
from oasis_torchrl.data.features import image_key
from oasis_torchrl.drivers.late_reaction import lane_keeping
from oasis_torchrl.models.checkpoint import save_checkpoint
from oasis_torchrl.models.config import DrivingNetConfig
from oasis_torchrl.models.encoder import MultiCameraEncoder
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, PRIVILEGED_KEY, privileged_state
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.simulator import Simulator, StepResult
from oasis_torchrl.train.mirror import Mirror
from oasis_torchrl.train.ppo import build_net

CHUNKS = 150
NOISE = (0.05, 0.02)
"""Standard deviations of the executed throttle and steering noise."""
REACTION = (5.0, 40.0)
"""Metres: the late-reacting episodes keep their lane until the obstacle is nearer than a draw."""
BATCH = 64


@dataclass
class Drives:
    """Rendered drives: each row's cameras' frames ``[N, C, H, W, 3]`` uint8, the row one chunk
    earlier in its episode (itself at an episode's start), the privileged state ``[N, F]``."""

    frames: torch.Tensor
    previous: torch.Tensor
    state: torch.Tensor

    def images(self, rows: torch.Tensor) -> list[torch.Tensor]:
        """Per camera, float ``[B, 2, 3, H, W]`` in ``[0, 1]``: the frames one chunk apart."""
        pair = torch.stack([self.frames[self.previous[rows]], self.frames[rows]], dim=2)
        pair = pair.movedim(-1, -3).float().div_(255)
        return list(pair.unbind(1))

    def head(self, rows: int) -> Drives:
        """The first ``rows`` rows (each row's previous one comes before it)."""
        return Drives(self.frames[:rows], self.previous[:rows], self.state[:rows])


def render(
    prompts: list[str], seeds: range, size: tuple[int, int], rng: np.random.Generator
) -> Drives:
    """Drive one episode per seed (prompts in turn), every other one reacting late."""
    frames, previous, truths = [], [], []
    for episode, seed in enumerate(tqdm(seeds, desc="drives", unit="episode")):
        sim = Simulator(size[1], size[0])
        sim.reset(prompts[episode % len(prompts)], seed)
        autopilot, late, reaction = Autopilot(sim), episode % 2 == 1, REACTION[1]
        last = _cameras(sim.step(np.zeros((4, 2), np.float32), last_only=True), sim)
        start = len(frames)
        for _ in range(CHUNKS):
            actions, truth = autopilot.act(), sim.truth
            previous.append(max(start, len(frames) - 1))
            frames.append(last)
            truths.append([getattr(truth, field) for field in PRIVILEGED_FIELDS])
            if truth.lane_obstacle_distance > REACTION[1]:
                reaction = rng.uniform(*REACTION)
            if late and truth.lane_obstacle_distance > reaction:
                pose = (truth.lane_offset, truth.heading_error, truth.speed)
                actions[:, 1] = float(lane_keeping(*map(torch.tensor, pose)))
            executed = np.clip(actions + rng.normal(0.0, NOISE, actions.shape), -1.0, 1.0)
            result = sim.step(executed.astype(np.float32), last_only=True)
            last = _cameras(result, sim)
            if result.truth[-1].collided:
                break
        sim.close()
    columns = torch.tensor(np.array(truths, dtype=np.float32)).unbind(-1)
    state = privileged_state(dict(zip(PRIVILEGED_FIELDS, columns, strict=True)))
    return Drives(torch.from_numpy(np.stack(frames)), torch.tensor(previous), state)


def _cameras(result: StepResult, sim: Simulator) -> np.ndarray:
    """The step's last frame of every camera, ``[C, H, W, 3]``."""
    return np.stack([result.rgb[camera][-1] for camera in sim.camera_names])


def encoder_and_head(seed: int) -> nn.Sequential:
    """A fresh clones' encoder and a small head to the privileged state."""
    torch.manual_seed(seed)
    encoder = MultiCameraEncoder(DrivingNetConfig())
    head = nn.Sequential(
        nn.Linear(encoder.out_features, 256), nn.ReLU(), nn.Linear(256, len(PRIVILEGED_FIELDS))
    )
    return nn.Sequential(encoder, head)


def fit(drives: Drives, steps: int, mirror: float, model: nn.Sequential) -> nn.Sequential:
    """``model`` (an encoder then a head) fitted to ``drives``' privileged state."""
    keys = [image_key(camera) for camera in DrivingNetConfig().cameras]
    reflect = Mirror(keys, PRIVILEGED_FIELDS, share=mirror) if mirror else None
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    for _ in tqdm(range(steps), desc=f"fit {len(drives.state)} rows, mirror {mirror}", unit="step"):
        rows = torch.randint(len(drives.state), (BATCH,))
        batch = {
            PRIVILEGED_KEY: drives.state[rows],
            **dict(zip(keys, drives.images(rows), strict=True)),
        }
        if reflect is not None:
            batch = reflect(batch)
        loss = (model([batch[key] for key in keys]) - batch[PRIVILEGED_KEY]).square().mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    return model.eval()


@torch.no_grad()
def r_squared(model: nn.Module, drives: Drives) -> dict[str, float]:
    """Each field's share of variance explained on ``drives`` (0: no better than its mean)."""
    rows = torch.arange(len(drives.state))
    predicted = torch.cat([model(drives.images(part)) for part in rows.split(512)])
    return explained_variance(predicted, drives.state)


def fit_ppo_encoder(train: Drives, held_out: Drives, args: argparse.Namespace) -> dict[str, object]:
    """A fresh PPO network whose encoder and auxiliary head are fitted to ``train``, saved to
    ``args.ppo_checkpoint`` (its actor and critic as fresh); the fields' R^2 on ``held_out``.
    PPO from it is a ceiling, not PPO from scratch: its encoder learned from the autopilot's
    drives, env steps no PPO budget counts (``warmup.frames`` is the counted way)."""
    torch.manual_seed(args.seed)
    net = build_net(load_config("ppo"), DrivingNetConfig().cameras)
    model = fit(train, args.steps, 0.0, nn.Sequential(net.encoder, net.aux))
    save_checkpoint(args.ppo_checkpoint, net, source="benchmarks/perception_data.py")
    fields = r_squared(model, held_out)
    return {
        "checkpoint": args.ppo_checkpoint,
        "rows": len(train.state),
        "steps": args.steps,
        "mean": round(float(np.mean(list(fields.values()))), 3),
        "r2": fields,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=320, help="training drives")
    parser.add_argument("--held-out", type=int, default=32, help="evaluation drives (urban)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[9600, 0], help="rows (0: all)")
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument(
        "--mirror", type=float, default=0.5, help="share mirrored in the mirror runs"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--ppo-checkpoint",
        help="instead of the runs: fit a fresh PPO network's encoder and auxiliary head (the "
        "PPOConfig defaults) on every training row and save it here, for PPO's init_from",
    )
    args = parser.parse_args()
    size = DrivingNetConfig().image_size
    rng = np.random.default_rng(args.seed)
    train = render(list(TRAINING_PROMPTS), range(5000, 5000 + args.episodes), size, rng)
    held_out = render(["urban"], range(900_000, 900_000 + args.held_out), size, rng)
    if args.ppo_checkpoint:
        print(json.dumps(fit_ppo_encoder(train, held_out, args), indent=2))
        return
    smallest = min(s or len(train.state) for s in args.sizes)
    runs = [(smallest, 0.0), (smallest, args.mirror)]
    runs += [
        (s or len(train.state), 0.0) for s in args.sizes if (s or len(train.state)) != smallest
    ]
    results = []
    for rows, mirror in runs:
        model = encoder_and_head(args.seed)
        fields = r_squared(fit(train.head(rows), args.steps, mirror, model), held_out)
        results.append(
            {
                "rows": rows,
                "mirror": mirror,
                "mean": round(float(np.mean(list(fields.values()))), 3),
                "r2": fields,
            }
        )
    baseline = results[0]
    for result in results:  # R^2 gained over the baseline: the whole state and the lane ahead
        result["mean_gain"] = round(result["mean"] - baseline["mean"], 3)
        lane = "lane_obstacle_distance"
        result["lane_obstacle_gain"] = round(result["r2"][lane] - baseline["r2"][lane], 3)
    report = {
        "steps": args.steps,
        "batch": BATCH,
        "train_rows": len(train.state),
        "held_out_rows": len(held_out.state),
        "runs": results,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
