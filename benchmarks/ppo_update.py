"""One PPO update step: our loss (the encoder once per minibatch) vs ClipPPOLoss over the full
actor and critic operators (TorchRL's recipe for an ActorValueOperator), same run, same data.

Both compute the same loss and gradients (``tests/train/test_ppo_loss.py``); the baseline
runs the shared encoder once for the actor and once more for the critic. The network is the
PPO trainer's: the default network of :class:`~oasis_torchrl.config.PPOConfig` at 64x96 with
the privileged critic (4 inputs) and the auxiliary head; a minibatch holds the env's uint8
frames ``[B, 4, 64, 96, 3]`` per camera. A step is loss, backward and an Adam step; best of
several repeats.

Usage: ``python benchmarks/ppo_update.py [--batch 128 --repeats 5]``; prints JSON with
milliseconds per step and ``speedup`` (the baseline's time over ours; > 1: ours is faster).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import torch
from omegaconf import OmegaConf
from tensordict import TensorDict, TensorDictBase
from torchrl.objectives import ClipPPOLoss

from oasis_torchrl.config import load_config
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.models.actor_critic import FRAME_STACK
from oasis_torchrl.train.ppo_loss import PPO_TERMS, DrivingPPOLoss


def trainer_network() -> DrivingNet:
    """The network a PPO run from scratch trains (:class:`~oasis_torchrl.config.PPOConfig`)."""
    cfg = load_config("ppo")
    network = OmegaConf.to_container(cfg.network)
    size = tuple(cfg.env.image_size)
    return DrivingNet(DrivingNetConfig(image_size=size, critic_inputs=4, aux_outputs=4, **network))


def minibatch(net: DrivingNet, rows: int) -> TensorDictBase:
    """A collected minibatch: frames, state, privileged inputs, action, log-prob, targets."""
    height, width = net.config.image_size
    stack = (rows, net.config.frames, height, width, 3)
    frames = {
        camera: torch.randint(0, 256, stack, dtype=torch.uint8) for camera in net.config.cameras
    }
    batch = TensorDict(
        {FRAME_STACK: frames, "state": torch.rand(rows, 2), "critic_inputs": torch.rand(rows, 4)},
        [rows],
    )
    with torch.no_grad():
        batch = make_actor_critic(net).policy(batch)
    batch["advantage"] = torch.randn(rows, 1)
    batch["value_target"] = torch.randn(rows, 1)
    return batch


def ms_per_step(
    loss: Callable[[TensorDictBase], TensorDictBase],
    terms: tuple[str, ...],
    net: DrivingNet,
    batch: TensorDictBase,
    repeats: int,
) -> float:
    """Best-of-``repeats`` milliseconds of loss + backward + Adam step."""
    optimizer = torch.optim.Adam(net.parameters(), lr=1e-5)

    def step() -> None:
        losses = loss(batch.clone(False))
        optimizer.zero_grad(set_to_none=True)
        sum(losses[key] for key in terms).backward()
        optimizer.step()

    step()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(5):
            step()
        best = min(best, (time.perf_counter() - start) / 5)
    return best * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=128, help="minibatch size")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    torch.manual_seed(0)
    net = trainer_network()
    modules = make_actor_critic(net)
    batch = minibatch(net, args.batch)
    ours = DrivingPPOLoss(modules, aux_coeff=1.0)
    baseline = ClipPPOLoss(modules.policy, modules.value)
    times = {
        "clip_ppo_full_operators_ms": ms_per_step(baseline, PPO_TERMS, net, batch, args.repeats),
        "ours_ms": ms_per_step(ours, ours.terms, net, batch, args.repeats),
    }
    report = {
        "batch": args.batch,
        "threads": torch.get_num_threads(),
        **{key: round(value, 1) for key, value in times.items()},
        "speedup": round(times["clip_ppo_full_operators_ms"] / times["ours_ms"], 2),
        "note": "ours also computes the auxiliary loss, which the baseline leaves out",
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
