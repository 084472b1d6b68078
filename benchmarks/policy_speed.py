"""Per-sample speed of our driving network vs the reference SDK's SB3 CNN policy, same run,
same threads.

The reference SDK (decart-robotics' RL extras): one shared CNN per camera at 128x192 (conv 16 k5 s2,
conv 32 k3 s2, global average pool), the three concatenated and projected to 384, then
Stable-Baselines3's default PPO heads (two 64-unit MLPs for the policy and the value). Ours:
:class:`~oasis_torchrl.models.DrivingNet` (three convolutions over the last two frames of each
camera, a pooled 4x6 grid per camera, 256-unit actor and value MLPs; a 4-action chunk per call).

Cases, each the action (chunk) and the value for a batch, best of several repeats:

- ``act``: batch 1, inference mode (acting latency of one env row);
- ``batch``: batch 64, inference mode (collector throughput);
- ``train``: batch 64, forward and backward (PPO update throughput).

Sizes: the reference SDK at its 128x192, ours at its default 64x96 and at the reference SDK's
128x192 (the same input), with shared and separate camera weights. Reported as microseconds
per sample and the reference SDK's time over ours (``speedup``; > 1 means ours is faster).

Usage: ``python benchmarks/policy_speed.py [--threads 1 --repeats 5]``; prints JSON.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import torch
from torch import nn

from oasis_torchrl.models import CAMERAS, DrivingNet, DrivingNetConfig

PEER_SIZE = (128, 192)
CASES = {"act": (1, False), "batch": (64, False), "train": (64, True)}


class PeerPolicy(nn.Module):
    """The reference SDK's feature extractor plus SB3's default actor-critic MLP heads."""

    def __init__(self, cameras: int = len(CAMERAS)) -> None:
        super().__init__()
        self.cnn = nn.Sequential(
            nn.Conv2d(3, 16, 5, 2, 2),
            nn.ReLU(),
            nn.Conv2d(16, 32, 3, 2, 1),
            nn.ReLU(),
            nn.AdaptiveAvgPool2d(1),
            nn.Flatten(),
        )
        self.project = nn.Sequential(nn.Linear(32 * cameras, 384), nn.ReLU())
        self.pi = nn.Sequential(nn.Linear(384, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh())
        self.vf = nn.Sequential(nn.Linear(384, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh())
        self.action = nn.Linear(64, 2)
        self.value = nn.Linear(64, 1)

    def forward(self, images: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        batch = images[0].shape[0]
        per_camera = self.cnn(torch.cat(images)).reshape(len(images), batch, -1)
        features = self.project(per_camera.transpose(0, 1).reshape(batch, -1))
        return self.action(self.pi(features)), self.value(self.vf(features))


def ours(net: DrivingNet) -> Callable[[list[torch.Tensor]], tuple[torch.Tensor, torch.Tensor]]:
    """Our chunk and value for a list of camera images (state zero)."""

    def run(images: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        features = net.features(images, torch.zeros(images[0].shape[0], 2))
        return net.deterministic_chunk(features), net.value(features)

    return run


def time_per_sample(
    model: Callable[[list[torch.Tensor]], tuple[torch.Tensor, torch.Tensor]],
    parameters: list[nn.Parameter],
    size: tuple[int, int],
    frames: int,
    batch: int,
    train: bool,
    repeats: int,
) -> float:
    """Best-of-``repeats`` microseconds per sample (``frames`` per camera; 0: no time axis)."""
    shape = (batch, frames, 3, *size) if frames else (batch, 3, *size)
    images = [torch.rand(shape) for _ in CAMERAS]
    iterations = max(3, 256 // batch)

    def once() -> None:
        if train:
            action, value = model(images)
            (action.square().mean() + value.square().mean()).backward()
            for parameter in parameters:
                parameter.grad = None
        else:
            with torch.inference_mode():
                model(images)

    once()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(iterations):
            once()
        best = min(best, (time.perf_counter() - start) / (iterations * batch))
    return best * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)

    peer = PeerPolicy()
    models = {"peer_128x192": (peer, list(peer.parameters()), PEER_SIZE, 0)}
    for shared in (True, False):
        for size in ((64, 96), PEER_SIZE):
            net = DrivingNet(DrivingNetConfig(shared_encoder=shared, image_size=size))
            name = f"ours_{'shared' if shared else 'separate'}_{size[0]}x{size[1]}"
            models[name] = (ours(net), list(net.parameters()), size, net.config.frames)

    results: dict[str, dict[str, float]] = {}
    for name, (model, parameters, size, frames) in models.items():
        results[name] = {
            f"{case}_us_per_sample": round(
                time_per_sample(model, parameters, size, frames, batch, train, args.repeats), 1
            )
            for case, (batch, train) in CASES.items()
        }
    peer_times = results["peer_128x192"]
    speedup = {
        name: {key: round(peer_times[key] / value, 2) for key, value in times.items()}
        for name, times in results.items()
        if name != "peer_128x192"
    }
    params = {"peer": sum(p.numel() for p in peer.parameters())}
    params["ours_shared"] = sum(p.numel() for p in DrivingNet().parameters())
    params["ours_separate"] = sum(
        p.numel() for p in DrivingNet(DrivingNetConfig(shared_encoder=False)).parameters()
    )
    report = {
        "threads": args.threads,
        "us_per_sample": results,
        "speedup_vs_peer": speedup,
        "parameters": params,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
