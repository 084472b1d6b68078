"""What the auxiliary replay costs: one PPO update of a collected batch, with and without it,
same network, same data, same run.

The update is the trainer's (:class:`~oasis_torchrl.train.ppo_update.PPOUpdate` with the
:class:`~oasis_torchrl.config.PPOConfig` defaults: GAE, four passes of minibatches of 128 over a
batch of 512 env steps, the privileged critic and the auxiliary head, at 64x96); the replay adds
``aux_replay.steps`` (16) auxiliary-only minibatches of 128 drawn from a ring already holding
``--rows`` env steps. The batch is 8 rows of 64 chunks of random uint8 frames, with actions and
log-probabilities from the policy itself. Best of ``--repeats`` updates each.

Usage: ``python benchmarks/aux_replay_cost.py [--rows 4096 --repeats 3]``; prints JSON with
seconds per update and ``ratio`` (with the replay over without; > 1: the replay costs that much
more).
"""

from __future__ import annotations

import argparse
import json
import time

import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDict, TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from oasis_torchrl.config import load_config
from oasis_torchrl.envs.transforms import PRIVILEGED_FIELDS
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.models.actor_critic import FRAME_STACK
from oasis_torchrl.train.ppo_update import PPOUpdate

ROWS, CHUNKS = 8, 64


def network(cfg: DictConfig) -> DrivingNet:
    """A fresh network of ``cfg`` with the privileged critic and the auxiliary head."""
    fields = len(PRIVILEGED_FIELDS)
    return DrivingNet(
        DrivingNetConfig(
            image_size=tuple(cfg.env.image_size),
            critic_inputs=fields,
            aux_outputs=fields,
            **OmegaConf.to_container(cfg.network),
        )
    )


def observations(net: DrivingNet) -> TensorDict:
    """``[ROWS, CHUNKS]`` observations as the env gives them."""
    height, width = net.config.image_size
    shape = (ROWS, CHUNKS, net.config.frames, height, width, 3)
    frames = {c: torch.randint(0, 256, shape, dtype=torch.uint8) for c in net.config.cameras}
    return TensorDict(
        {
            FRAME_STACK: frames,
            "state": torch.rand(ROWS, CHUNKS, 2),
            "critic_inputs": torch.rand(ROWS, CHUNKS, len(PRIVILEGED_FIELDS)),
        },
        [ROWS, CHUNKS],
    )


def collected(net: DrivingNet) -> TensorDictBase:
    """A batch as the collector gives it: the policy's actions, rewards, next observations."""
    with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
        batch = make_actor_critic(net).policy(observations(net))
    running = torch.zeros(ROWS, CHUNKS, 1, dtype=torch.bool)
    batch["next"] = observations(net).update(
        {"reward": torch.randn(ROWS, CHUNKS, 1), "done": running, "terminated": running}
    )
    return batch


def seconds_per_update(cfg: DictConfig, batch: TensorDictBase, fill: int, repeats: int) -> float:
    """Best of ``repeats`` updates of a fresh network on ``batch`` (the replay, if configured,
    first filled with ``fill`` rows)."""
    torch.manual_seed(0)
    update = PPOUpdate(make_actor_critic(network(cfg)), cfg, total_frames=10 * batch.numel())
    if update.aux_replay is not None:
        flat = batch.exclude("next").reshape(-1)
        while len(update.aux_replay) < fill:
            update.aux_replay.extend(flat)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        update(batch, frames=batch.numel())
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=4096, help="env steps in the ring")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.manual_seed(0)
    plain = load_config("ppo")
    replay = load_config("ppo", [f"aux_replay.capacity={args.rows}"])
    batch = collected(network(plain))
    without = seconds_per_update(plain, batch, 0, args.repeats)
    with_replay = seconds_per_update(replay, batch, args.rows, args.repeats)
    report = {
        "env_steps_per_batch": batch.numel(),
        "replay_rows": args.rows,
        "replay_steps": replay.aux_replay.steps,
        "threads": torch.get_num_threads(),
        "without_replay_s": round(without, 3),
        "with_replay_s": round(with_replay, 3),
        "ratio": round(with_replay / without, 2),
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
