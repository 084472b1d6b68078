"""How well camera clones see: the error of their auxiliary heads on the frames they act on.

A camera clone learns, beside the actions, to predict the simulator's privileged state
(:data:`~oasis_torchrl.models.privileged.PRIVILEGED_FIELDS`) from its cameras. A state clone
handed that state exactly drives nearly as far as the autopilot (``state_clone.py``), so how well
the cameras give it is the question for a camera clone. Driving evaluations answer it slowly and
noisily (one collision more or less moves a 32-episode mean by metres); this script measures it
directly.

The autopilot drives the evaluation's episodes (the env's own per-episode seeds) with Gaussian
noise on every executed action, so the states include recoveries. At every chunk the world
renders the cameras at each network's image size, as the embedded server streams them, and each
network predicts the state from its last ``frames`` chunks' frames. The figure per field is the
fraction of its variance explained (R^2): the prediction's squared error against that of the
baseline in the same run, always answering the field's mean over the run (0: no better than the
mean, 1: exact).

Usage: ``python benchmarks/perception.py POLICY [POLICY ...] [--episodes 16 --prompts urban]``
(policy folders of behaviour cloning with ``policy.aux_weight > 0``, or PPO checkpoints with an
auxiliary head); prints JSON (about a minute per policy on 2 cores).
"""

from __future__ import annotations

import argparse
import json
from collections import deque
from collections.abc import Iterator, Sequence

import numpy as np
import torch
from state_clone import evaluation_episodes, state_of
from tqdm import tqdm

from oasis_torchrl.drivers.folders import load_net
from oasis_torchrl.models import DrivingNet
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.simulator import Simulator


def load_clones(paths: Sequence[str]) -> dict[str, DrivingNet]:
    """The networks at ``paths``, each with an auxiliary head for the privileged fields."""
    nets = {}
    for path in paths:
        net = load_net(path).eval()
        if net.config.aux_outputs != len(PRIVILEGED_FIELDS):
            raise ValueError(
                f"{path} has no auxiliary head for the {len(PRIVILEGED_FIELDS)} privileged "
                f"fields (aux_outputs={net.config.aux_outputs}): train it with aux_weight > 0"
            )
        nets[path] = net
    return nets


def episode_chunks(
    prompt: str, seed: int, size: tuple[int, int], frames: int, args: argparse.Namespace
) -> Iterator[tuple[list[np.ndarray], torch.Tensor]]:
    """One noisy autopilot episode at ``(height, width)``: from its ``frames``-th chunk on, each
    camera's last ``frames`` chunk-end frames ``[frames, H, W, 3]`` and the scaled state then."""
    rng = np.random.default_rng(seed)
    simulator = Simulator(size[1], size[0])
    simulator.reset(prompt, seed)
    pilot = Autopilot(simulator)
    history = {camera: deque(maxlen=frames) for camera in simulator.camera_names}
    for _ in range(args.max_steps):
        chunk = pilot.act() + args.noise * rng.standard_normal((4, 2))
        result = simulator.step(np.clip(chunk, -1, 1).astype(np.float32), last_only=True)
        for camera, frame in result.rgb.items():
            history[camera].append(frame[0])
        if len(history["front"]) == frames:
            images = [np.stack(history[camera]) for camera in simulator.camera_names]
            yield images, state_of(result.truth[-1], PRIVILEGED_FIELDS)
        if result.truth[-1].collided:
            return


@torch.no_grad()
def predictions(
    net: DrivingNet, prompts: Sequence[str], seeds: Sequence[int], args: argparse.Namespace
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(predicted, true)`` scaled states ``[rows, fields]`` of ``net`` on the episodes."""
    size, frames = tuple(net.config.image_size), net.config.frames
    predicted, true = [], []
    for prompt, seed in zip(prompts, seeds, strict=True):
        rows = list(episode_chunks(prompt, seed, size, frames, args))
        if not rows:
            continue
        cameras = zip(*(images for images, _ in rows), strict=True)
        images = [torch.from_numpy(np.stack(frames)) for frames in cameras]
        state = torch.zeros(len(rows), net.config.state_dim)
        predicted.append(net.predict_aux(net.features(images, state)))
        true.append(torch.stack([r[1] for r in rows]))
    return torch.cat(predicted), torch.cat(true)


def explained_variance(predicted: torch.Tensor, true: torch.Tensor) -> dict[str, float]:
    """R^2 per field: 1 - the prediction's squared error / the run mean's."""
    error = ((predicted - true) ** 2).sum(0)
    baseline = ((true - true.mean(0)) ** 2).sum(0).clamp_min(1e-12)
    return {
        field: round(float(1 - e / b), 3)
        for field, e, b in zip(PRIVILEGED_FIELDS, error, baseline, strict=True)
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policies", nargs="+", help="camera clones with an auxiliary head")
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--eval-seed", type=int, default=1000)
    parser.add_argument("--prompts", nargs="+", default=["urban"])
    parser.add_argument("--max-steps", type=int, default=150, help="chunks per episode")
    parser.add_argument("--noise", type=float, default=0.05, help="executed-action noise std")
    args = parser.parse_args()

    torch.manual_seed(0)
    nets = load_clones(args.policies)
    episodes = [
        evaluation_episodes(prompt, args.eval_seed, args.episodes) for prompt in args.prompts
    ]
    prompts = [prompt for scene in episodes for prompt in scene[0]]
    seeds = [seed for scene in episodes for seed in scene[1]]
    report: dict[str, object] = {"settings": vars(args), "fields": list(PRIVILEGED_FIELDS)}
    for path, net in tqdm(nets.items(), desc="policies", unit="policy"):
        predicted, true = predictions(net, prompts, seeds, args)
        per_field = explained_variance(predicted, true)
        report[path] = {
            "rows": len(true),
            "r2": per_field,
            "mean_r2": round(float(np.mean(list(per_field.values()))), 3),
            "mean_abs_error": round(float((predicted - true).abs().mean()), 4),
        }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
