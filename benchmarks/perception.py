"""How well camera clones see: the error of their auxiliary heads on the frames they act on.

A camera clone learns, beside the actions, to predict the simulator's privileged state
(:data:`~oasis_torchrl.models.privileged.PRIVILEGED_FIELDS`) from its cameras. A state clone
handed that state exactly drives nearly as far as the autopilot (``state_clone.py``), so how well
the cameras give it is the question for a camera clone. Driving evaluations answer it slowly and
noisily (one collision more or less moves a 32-episode mean by metres); this script measures it
directly.

The autopilot drives the evaluation's episodes (the env's own per-episode seeds) with Gaussian
noise on every executed action, so the states include recoveries; with ``--own-drives`` each
network drives them itself (its deterministic chunk, the same noise), which measures how well a
policy sees on the states it reaches rather than on the autopilot's. At every chunk the world
renders the cameras at each network's image size, as the embedded server streams them, and each
network predicts the state from its last ``frames`` chunks' frames. The figure per field is the
fraction of its variance explained (R^2): the prediction's squared error against that of the
baseline in the same run, always answering the field's mean over the run (0: no better than the
mean, 1: exact).

On the same frames it also compares what each clone would do with what the autopilot does: how
often each one's chunk steers (mean ``|steering|`` above :data:`STEERS`: a lane change) and how
their steering correlates. A clone can read the state well and still rarely commit to a lane
change.

Usage: ``python benchmarks/perception.py [POLICY ...] [--episodes 16 --prompts urban]
[--own-drives]``
(policy folders of behaviour cloning with ``policy.aux_weight > 0``, or PPO checkpoints with an
auxiliary head; default: the learning benchmark's clones, without and with DAgger, under its
default ``--work``); prints JSON (about a minute per policy on 2 cores).
"""

from __future__ import annotations

import argparse
import json
from collections import deque
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import torch
from state_clone import evaluation_episodes, load_camera_clone, state_of
from tqdm import tqdm

from oasis_torchrl.models import DrivingNet
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS
from oasis_torchrl.protocol import ACTION_DIM, CHUNK
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.simulator import Simulator

LEARNING_CLONES = ("outputs/learning/bc/round_0/policy", "outputs/learning/bc/round_3/policy")
"""The learning benchmark's clones without and with its 3 DAgger rounds (its default ``--work``)."""
STEERS = 0.1
"""A chunk steers when its mean ``|steering|`` is above this (a lane change's is 0.1-0.5)."""


def load_clones(paths: Sequence[str]) -> dict[str, DrivingNet]:
    """The networks at ``paths``, each with an auxiliary head for the privileged fields."""
    nets = {}
    for path in paths:
        if not Path(path).exists():
            raise FileNotFoundError(
                f"no policy at {path}: name clones to measure, or run benchmarks/learning.py "
                "--stages references bc bc_dagger first (its clones are the default)"
            )
        nets[path] = load_camera_clone(path)
    return nets


def episode_chunks(
    prompt: str,
    seed: int,
    net: DrivingNet,
    args: argparse.Namespace,
) -> Iterator[tuple[list[np.ndarray], torch.Tensor, np.ndarray, np.ndarray]]:
    """One noisy episode at ``net``'s image size, driven by the autopilot or, with
    ``args.own_drives``, by ``net``'s deterministic chunk once it has its frames: from its
    ``frames``-th chunk on, each camera's last ``frames`` chunk-end frames ``[frames, H, W, 3]``,
    the scaled state then, the chunk ``[4, 2]`` the autopilot chooses there and the driver's
    previous chunk (before the noise)."""
    rng = np.random.default_rng(seed)
    size, frames = tuple(net.config.image_size), net.config.frames
    simulator = Simulator(size[1], size[0])
    simulator.reset(prompt, seed)
    pilot = Autopilot(simulator)
    history = {camera: deque(maxlen=frames) for camera in simulator.camera_names}
    previous = np.zeros((CHUNK, ACTION_DIM), np.float32)
    for _ in range(args.max_steps):
        chunk = driven = pilot.act()
        if len(history["front"]) == frames:
            images = [np.stack(history[camera]) for camera in simulator.camera_names]
            yield images, state_of(simulator.truth, PRIVILEGED_FIELDS), chunk, previous
            if args.own_drives:
                driven = own_chunk(net, images, previous)
        executed = np.clip(driven + args.noise * rng.standard_normal(driven.shape), -1, 1)
        result = simulator.step(executed.astype(np.float32), last_only=True)
        previous = driven
        for camera, frame in result.rgb.items():
            history[camera].append(frame[0])
        if result.truth[-1].collided:
            return


@torch.no_grad()
def own_chunk(net: DrivingNet, images: Sequence[np.ndarray], previous: np.ndarray) -> np.ndarray:
    """``net``'s deterministic chunk ``[4, 2]`` on one chunk's frames and its previous chunk."""
    frames = [torch.from_numpy(image)[None] for image in images]
    features = net.features(frames, torch.from_numpy(previous[-1])[None].float())
    return net.deterministic_chunk(features)[0].numpy()


@torch.no_grad()
def predictions(
    net: DrivingNet, prompts: Sequence[str], seeds: Sequence[int], args: argparse.Namespace
) -> dict[str, torch.Tensor]:
    """On the episodes, per chunk: the scaled state ``"true"`` and ``net``'s prediction of it
    ``"predicted"`` ``[rows, fields]``; the autopilot's chunk ``"expert"`` and ``net``'s
    deterministic one ``"clone"`` ``[rows, 4, 2]`` (the previous action it may read: the
    driver's)."""
    columns: dict[str, list[torch.Tensor]] = {
        "true": [],
        "predicted": [],
        "expert": [],
        "clone": [],
    }
    for prompt, seed in zip(prompts, seeds, strict=True):
        rows = list(episode_chunks(prompt, seed, net, args))
        if not rows:
            continue
        images, truths, expert, previous = zip(*rows, strict=True)
        cameras = [torch.from_numpy(np.stack(frames)) for frames in zip(*images, strict=True)]
        state = torch.from_numpy(np.stack(previous)[:, -1]).float()
        features = net.features(cameras, state)
        columns["predicted"].append(net.predict_aux(features))
        columns["clone"].append(net.deterministic_chunk(features))
        columns["true"].append(torch.stack(truths))
        columns["expert"].append(torch.from_numpy(np.stack(expert)).float())
    return {name: torch.cat(values) for name, values in columns.items()}


def steering(expert: torch.Tensor, clone: torch.Tensor) -> dict[str, float]:
    """How often each steers (a chunk's mean ``|steering|`` above :data:`STEERS`) and how the
    two chunks' mean steering correlate."""
    expert, clone = expert[..., 1].mean(-1), clone[..., 1].mean(-1)
    return {
        "expert_steers": round(float((expert.abs() > STEERS).float().mean()), 4),
        "clone_steers": round(float((clone.abs() > STEERS).float().mean()), 4),
        "correlation": round(float(torch.corrcoef(torch.stack([expert, clone]))[0, 1]), 3),
    }


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
    parser.add_argument(
        "policies",
        nargs="*",
        default=list(LEARNING_CLONES),
        help="camera clones with an auxiliary head (default: the learning benchmark's)",
    )
    parser.add_argument("--episodes", type=int, default=16)
    parser.add_argument("--eval-seed", type=int, default=1000)
    parser.add_argument("--prompts", nargs="+", default=["urban"])
    parser.add_argument("--max-steps", type=int, default=150, help="chunks per episode")
    parser.add_argument("--noise", type=float, default=0.05, help="executed-action noise std")
    parser.add_argument(
        "--own-drives",
        action="store_true",
        help="each network drives its episodes (deterministic chunks, the same noise) instead "
        "of the autopilot: how well it sees where it drives",
    )
    args = parser.parse_args()

    nets = load_clones(args.policies)
    episodes = [
        evaluation_episodes(prompt, args.eval_seed, args.episodes) for prompt in args.prompts
    ]
    prompts = [prompt for scene in episodes for prompt in scene[0]]
    seeds = [seed for scene in episodes for seed in scene[1]]
    report: dict[str, object] = {"settings": vars(args), "fields": list(PRIVILEGED_FIELDS)}
    for path, net in tqdm(nets.items(), desc="policies", unit="policy"):
        rows = predictions(net, prompts, seeds, args)
        per_field = explained_variance(rows["predicted"], rows["true"])
        report[path] = {
            "rows": len(rows["true"]),
            "r2": per_field,
            "mean_r2": round(float(np.mean(list(per_field.values()))), 3),
            "mean_abs_error": round(float((rows["predicted"] - rows["true"]).abs().mean()), 4),
            "steering": steering(rows["expert"], rows["clone"]),
        }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
