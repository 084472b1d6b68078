"""PPO from scratch on the privileged state: does PPO lack perception or exploration?

PPO from scratch on the cameras learns no reaction to obstacles within 204,800 env steps
(BENCHMARKS.md, "crashes.py"): it finds a local optimum that pays without seeing (one
throttle, the line between two lanes). Two things could hold it there: the cameras (the encoder
must learn to see an obstacle in a lane before the actor can react to it) or exploration (a lane
change must be found by per-chunk noise). This script removes the first: the same PPO (the
``PPOConfig`` defaults: mixture head, its initial action and scales, loss, optimiser, reward,
five training scenes, 8 rows, batches of 512 env steps) with the cameras' encoder replaced by one
layer on :data:`~oasis_torchrl.models.privileged.PRIVILEGED_FIELDS` (the lane-centred state from
which a clone of the autopilot drives 96% of it, ``state_clone.py``), on the simulator's physics
alone (no frames rendered, so about ten times faster). If PPO reaches the targets here, what the
camera runs lack is perception, and a privileged teacher distilled into the cameras is the way;
if it does not, exploration is.

Every ``--eval-every`` env steps the policy drives the selection episodes (urban, seed 2000,
32 episodes of up to 150 chunks, deterministic); the best is kept and reported on the learning
benchmark's evaluation episodes (urban, seed 1000), against the best constant action there.

The loop is TorchRL's Collector over this script's env feeding the trainer's update
(:class:`~oasis_torchrl.train.ppo_update.PPOUpdate`: GAE, the loss, the optimiser and its
schedule), so only the env and the network's input differ from ``PPOTrainer``'s runs.

Usage: ``python benchmarks/state_ppo.py [--frames 204800 --seeds 0 1]``; prints JSON (about
5 min per seed on 2 cores).
"""

from __future__ import annotations

import argparse
import copy
import json
from collections.abc import Sequence

import torch
from omegaconf import DictConfig, OmegaConf
from state_clone import state_of
from tensordict import NonTensorStack, TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import Bounded, Categorical, Composite, NonTensor, Unbounded
from torchrl.envs import EnvBase
from tqdm import tqdm

from oasis_torchrl.config import load_config
from oasis_torchrl.config.pipeline import TRAINING_PROMPTS
from oasis_torchrl.envs.episodes import EpisodePlanner, episode_prompts
from oasis_torchrl.envs.factory import make_reward
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.models.actor_critic import FEATURES
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS
from oasis_torchrl.sim.simulator import Simulator
from oasis_torchrl.sim.world import FrameTruth
from oasis_torchrl.train.evaluate import EvalReport, episode_results, rollout_episodes
from oasis_torchrl.train.ppo_update import PPOUpdate

OBSERVATION = "observation"
TRUTH_FIELDS = ("progress", "distance", "collided", "lane_offset", "obstacle_distance")
"""The ground truth of every frame a step returns: what the reward and the evaluation read."""
BEST_CONSTANT = 192.4
"""Full throttle, straight, on the evaluation episodes (BENCHMARKS.md, "Learning")."""


class StateDrivingEnv(EnvBase):
    """``rows`` simulators stepped on physics alone; the observation is the privileged state of
    each row's last frame and its previous action, the reward the training env's
    (``make_reward(cfg.reward)``), an episode ends at a collision or after ``max_steps``."""

    def __init__(
        self, prompts: Sequence[str], rows: int, max_steps: int, reward_cfg: DictConfig, seed: int
    ) -> None:
        super().__init__(batch_size=torch.Size([rows]))
        self.simulators = [Simulator(96, 64) for _ in range(rows)]
        self.planner = EpisodePlanner(episode_prompts(prompts), num_rows=rows)
        self.planner.set_seed(seed)
        self.reward = make_reward(reward_cfg)
        self.max_steps = max_steps
        self.steps = torch.zeros(rows, dtype=torch.long)
        self.previous = torch.zeros(rows, 2)
        self.prompts = [""] * rows
        self.seeds = torch.zeros(rows, 1, dtype=torch.int64)
        width = len(PRIVILEGED_FIELDS) + 2
        self.observation_spec = Composite(
            {
                OBSERVATION: Unbounded((rows, width)),
                "prompt": NonTensor(shape=(rows,), example_data="urban"),
                "episode_seed": Unbounded((rows, 1), dtype=torch.int64),
                "truth": Composite(
                    {field: Unbounded((rows, 4)) for field in TRUTH_FIELDS}, shape=self.batch_size
                ),
            },
            shape=self.batch_size,
        )
        flags = {
            flag: Categorical(2, (rows, 1), dtype=torch.bool)
            for flag in ("done", "terminated", "truncated")
        }
        self.done_spec = Composite(flags, shape=self.batch_size)
        self.action_spec = Bounded(-1.0, 1.0, (rows, 4, 2))
        self.reward_spec = Unbounded((rows, 1))

    def _observation(self) -> TensorDict:
        """Each row's observation, and its episode's prompt and seed (as the camera env
        gives them, so the project's evaluation reads these rollouts)."""
        state = torch.stack(
            [state_of(simulator.truth, PRIVILEGED_FIELDS) for simulator in self.simulators]
        )
        return TensorDict(
            {
                OBSERVATION: torch.cat([state, self.previous], dim=-1),
                "prompt": NonTensorStack(*self.prompts),
                "episode_seed": self.seeds.clone(),
            },
            self.batch_size,
        )

    def _reset(self, tensordict: TensorDictBase | None) -> TensorDictBase:
        mask = torch.ones(self.batch_size, dtype=torch.bool)
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(-1)
        rows = mask.nonzero().flatten().tolist()
        prompts, seeds = self.planner.next_episodes(rows)
        for row, prompt, seed in zip(rows, prompts, seeds, strict=True):
            self.simulators[row].reset(prompt, seed)
            self.prompts[row], self.seeds[row] = prompt, seed
        self.steps[mask] = 0
        self.previous[mask] = 0.0
        self.reward.reset(mask)
        return self._observation().update(
            {"truth": self._truth([[s.truth] for s in self.simulators])}
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.get("action").clamp(-1.0, 1.0)
        frames = [
            simulator.step(chunk.numpy(), render=False).truth
            for simulator, chunk in zip(self.simulators, actions, strict=True)
        ]
        truth = self._truth(frames)
        out = self.reward(TensorDict({"truth": truth}, self.batch_size))
        self.steps += 1
        self.previous = actions[:, -1].clone()
        terminated = out.get("terminated").reshape(-1, 1)
        truncated = (self.steps >= self.max_steps).reshape(-1, 1) & ~terminated
        return self._observation().update(
            {
                "truth": truth,
                "reward": out.get("reward").reshape(-1, 1),
                "terminated": terminated,
                "truncated": truncated,
                "done": terminated | truncated,
            }
        )

    def _truth(self, frames: Sequence[Sequence[FrameTruth]]) -> TensorDict:
        """``TRUTH_FIELDS`` of each row's frames ``[rows, 4]`` (a reset's one frame repeated)."""
        values = {
            field: torch.tensor([[float(getattr(f, field)) for f in row] for row in frames])
            for field in TRUTH_FIELDS
        }
        return TensorDict({k: v.expand(-1, 4) for k, v in values.items()}, self.batch_size)

    def _set_seed(self, seed: int | None) -> None:
        self.planner.set_seed(seed or 0)


class _StateFeatures(nn.Module):
    """``[*B, fields + 2] -> [*B, features_dim]``: one layer over the privileged state in place
    of the cameras' encoder, then the previous action, as ``DrivingNet.features`` lays them."""

    def __init__(self, net: DrivingNet) -> None:
        super().__init__()
        width = net.config.features_dim - net.config.state_dim
        self.layer = nn.Sequential(nn.Linear(len(PRIVILEGED_FIELDS), width), nn.ReLU())

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        state, previous = observation[..., :-2], observation[..., -2:]
        return torch.cat([self.layer(state), previous], dim=-1)


def state_policy(cfg: DictConfig) -> tuple[DrivingNet, TensorDictModule]:
    """The PPO config's fresh network (its heads, initial action and scales) and the
    shared part that feeds them the privileged state."""
    network = OmegaConf.to_container(cfg.network)
    net = DrivingNet(DrivingNetConfig.from_dict({**network, "image_size": (64, 96)}))
    features = TensorDictModule(_StateFeatures(net), in_keys=[OBSERVATION], out_keys=[FEATURES])
    return net, features


def evaluate(
    policy: TensorDictModule, cfg: DictConfig, seed: int, episodes: int, max_steps: int = 150
) -> dict[str, float]:
    """Deterministic episodes on "urban" (one per row, seeded as the env seeds them), read as
    the project's evaluation reads them: mean distance before a collision, collision rate,
    return."""
    env = StateDrivingEnv(["urban"], episodes, max_steps, cfg.env.reward, seed)
    return EvalReport(episode_results(rollout_episodes(env, policy, max_steps))).summary()


def train(seed: int, args: argparse.Namespace) -> dict:
    """One PPO run; its selection curve and the kept policy's evaluation."""
    cfg = load_config("ppo", list(args.overrides))
    torch.manual_seed(seed)
    net, features = state_policy(cfg)
    modules = make_actor_critic(net, features=features)
    update = PPOUpdate(modules, cfg, args.frames)
    env = StateDrivingEnv(
        TRAINING_PROMPTS, cfg.env.num_envs, cfg.env.max_steps, cfg.env.reward, seed
    )
    collector = Collector(
        env,
        modules.policy,
        frames_per_batch=cfg.collector.frames_per_batch,
        total_frames=args.frames,
    )
    curve, kept, frames = [], {}, 0
    bar = tqdm(collector, total=args.frames // cfg.collector.frames_per_batch, desc=f"seed {seed}")
    for batch in bar:
        frames += batch.numel()
        update(batch, frames)
        if frames % args.eval_every == 0:
            rated = evaluate(modules.policy, cfg, args.selection_seed, args.episodes)
            scale = list(update.scale_metrics().values())  # [throttle, steering]
            curve.append({"frames": frames, "scale": scale, **rated})
            kept[frames] = copy.deepcopy(modules.policy.state_dict())
            bar.set_postfix(selection=f"{rated['mean_distance']:.1f} m")
    collector.shutdown()
    reports = {}
    for budget in sorted({*args.budgets, args.frames}):
        best = max(
            (point for point in curve if point["frames"] <= budget),
            key=lambda point: point["mean_distance"],
        )
        modules.policy.load_state_dict(kept[best["frames"]])
        final = evaluate(modules.policy, cfg, args.eval_seed, args.episodes)
        reports[str(budget)] = {
            "kept_frames": best["frames"],
            "selection": best["mean_distance"],
            **final,
            "over_best_constant": final["mean_distance"] / BEST_CONSTANT,
        }
    return {"seed": seed, "curve": curve, "within": reports}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=204800)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--eval-every", type=int, default=10240)
    parser.add_argument("--budgets", type=int, nargs="+", default=[102400])
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--selection-seed", type=int, default=2000)
    parser.add_argument("--eval-seed", type=int, default=1000)
    parser.add_argument("overrides", nargs="*", help="PPOConfig overrides, e.g. loss.gamma=0.99")
    args = parser.parse_args()
    runs = [train(seed, args) for seed in args.seeds]
    print(json.dumps({"settings": vars(args), "runs": runs}, indent=2))


if __name__ == "__main__":
    main()
