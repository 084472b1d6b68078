"""What PPO collects with against what it is evaluated with: a mixture policy driven by its
deterministic action and by samples of its distribution, on the same episodes.

PPO's collector samples the action chunk (a component drawn from the mixture's weights every
chunk, then its normal deviations; ``exploration.hold_chunks`` 1); every evaluation drives the
deterministic action, the most probable component's chunk. This script drives one policy through
the learning benchmark's evaluation episodes (urban, seed 1000, 32 episodes of up to 150 chunks)
four ways and reports each against the deterministic one (the baseline, the same run):

- ``deterministic``: the most probable component's ``tanh(loc)``, what evaluations drive;
- ``sampled``: a component drawn from the weights, then ``tanh(loc + scale * noise)``, what
  PPO collects with;
- ``components``: a component drawn from the weights, no deviations;
- ``deviations``: the most probable component, with the deviations.

Usage: ``python benchmarks/sampled_policy.py POLICY [--episodes 32 --seed 1000]`` (a PPO
checkpoint or a LeRobot policy folder of type ``oasis``); prints JSON (about a minute per mode on
2 cores). The draws are seeded with ``--seed``, so a run repeats to the digit.
"""

from __future__ import annotations

import argparse
import json

import torch
from tensordict.nn import TensorDictModule

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers.folders import load_net
from oasis_torchrl.drivers.policy import PolicyDriver
from oasis_torchrl.models import DrivingNet
from oasis_torchrl.models.actor_critic import observation_keys, observation_spec
from oasis_torchrl.models.config import MIXTURE
from oasis_torchrl.models.distributions import TanhNormalMixture
from oasis_torchrl.train.evaluate import Evaluator

MODES = ("deterministic", "sampled", "components", "deviations")


def act(dist: TanhNormalMixture, mode: str) -> torch.Tensor:
    """The action chunk of ``mode`` (see the module's docs)."""
    if mode == "deterministic":
        return dist.deterministic_sample
    if mode == "sampled":
        return dist.sample()
    if mode == "components":
        uniform = torch.rand(dist.batch_shape)
        return dist.from_noise(uniform, torch.zeros(*dist.batch_shape, *dist.event_shape))
    if mode == "deviations":
        normal = torch.randn(*dist.batch_shape, *dist.event_shape)
        return dist.component_chunk(dist.logits.argmax(-1), normal)
    raise ValueError(f"unknown mode {mode!r}")


class ModeActor(torch.nn.Module):
    """The network's action chunk under one ``mode``, from its observation keys' tensors."""

    def __init__(self, net: DrivingNet, mode: str) -> None:
        super().__init__()
        self.net, self.mode = net, mode

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        *images, state = inputs
        dist = self.net.distribution(self.net.features(images, state))
        return act(dist, self.mode)


def evaluate(net: DrivingNet, mode: str, args: argparse.Namespace) -> dict[str, float]:
    """Mean distance and collision rate of ``net`` driven by ``mode`` on the evaluation."""
    cfg = load_config(
        "eval",
        [
            f"episodes={args.episodes}",
            f"seeds=[{args.seed}]",
            f"max_steps={args.max_steps}",
            f"prompts=[{args.prompt}]",
        ],
    )
    module = TensorDictModule(
        ModeActor(net, mode), in_keys=observation_keys(net), out_keys=["action"]
    )
    driver = PolicyDriver(
        module,
        image_size=tuple(net.config.image_size),
        frame_stack=net.config.frames,
        observation_spec=observation_spec(net),
    )
    torch.manual_seed(args.seed)
    with torch.no_grad(), Evaluator.for_driver(cfg.env, cfg, driver, progress=False) as evaluator:
        report = evaluator.evaluate(driver)
    return {"mean_distance": report.mean_distance, "collision_rate": report.collision_rate}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", help="a PPO checkpoint or a LeRobot policy folder (oasis)")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--max-steps", type=int, default=150, help="chunks per episode")
    parser.add_argument("--prompt", default="urban")
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    args = parser.parse_args()
    net = load_net(args.policy).eval()
    if net.config.head != MIXTURE:
        parser.error(f"{args.policy} has the {net.config.head} head; this compares a mixture's")
    results: dict = {"policy": args.policy, "episodes": args.episodes, "seed": args.seed}
    for mode in args.modes:
        results[mode] = evaluate(net, mode, args)
    baseline = results.get("deterministic")
    for mode in args.modes:
        if baseline and mode != "deterministic":
            ratio = results[mode]["mean_distance"] / baseline["mean_distance"]
            results[mode]["vs_deterministic"] = round(ratio, 3)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
