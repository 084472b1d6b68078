"""PPO in the Oasis world model with plain TorchRL parts, in the style of TorchRL's
``sota-implementations/ppo``: your env, transforms, networks, collector, loss and logger.

The env is ``OasisEnv`` (here on the embedded local simulator; pass an endpoint for a remote A2V
server or the hosted model). Everything else is stock TorchRL, so swap in your own parts.

    python examples/ppo_torchrl.py                   # a short run; curves in outputs/examples/ppo
    OASIS_EXAMPLE_SMOKE=1 python examples/ppo_torchrl.py   # a few steps (what the tests run)
"""

from __future__ import annotations

import os

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
from torchrl.envs import CatTensors, Compose, RewardSum, StepCounter, ToTensorImage, TransformedEnv
from torchrl.modules import MLP, ConvNet, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE
from torchrl.record.loggers import get_logger

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig

SMOKE = os.environ.get("OASIS_EXAMPLE_SMOKE") == "1"
CAMERAS = ("left_forward", "front", "right_forward")
NUM_ENVS = 2 if SMOKE else 8
IMAGE_SIZE = (32, 48) if SMOKE else (64, 96)  # (height, width) the frames are decoded to
FRAMES_PER_BATCH = 8 if SMOKE else 512  # env steps per batch, all rows together
TOTAL_FRAMES = 16 if SMOKE else 40_960
MINI_BATCH = 4 if SMOKE else 128
EPOCHS = 1 if SMOKE else 4
LR = 3e-4
OUTPUT = "outputs/examples/ppo"


def make_env() -> TransformedEnv:
    """N sessions of the world model as one batched env, frames as float CHW images."""
    env = OasisEnv(
        "local",
        num_envs=NUM_ENVS,
        prompts="urban street",
        server=ServerConfig(width=IMAGE_SIZE[1], height=IMAGE_SIZE[0]),
        chunk_actions=False,  # [N, 2] actions, each applied to the 4 frames of a chunk
        max_steps=8 if SMOKE else 200,
    )
    pixels = [("pixels", camera) for camera in CAMERAS]
    return TransformedEnv(
        env,
        Compose(
            ToTensorImage(in_keys=pixels),  # uint8 HWC -> float CHW in [0, 1]
            CatTensors(in_keys=pixels, out_key="cameras", dim=-3),  # 3 cameras -> 9 channels
            RewardSum(),
            StepCounter(),
        ),
    )


def make_modules(env: TransformedEnv) -> tuple[ProbabilisticActor, ValueOperator]:
    """A small CNN actor (TanhNormal over throttle and steering) and a CNN critic."""
    action_spec = env.action_spec_unbatched

    def encoder(out_features: int) -> nn.Sequential:
        conv = ConvNet(num_cells=[16, 32, 32], kernel_sizes=[5, 3, 3], strides=[2, 2, 2])
        return nn.Sequential(conv, MLP(out_features=out_features, num_cells=[128]))

    actor_net = nn.Sequential(encoder(2 * action_spec.shape[-1]), NormalParamExtractor())
    actor = ProbabilisticActor(
        TensorDictModule(actor_net, in_keys=["cameras"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"],
        spec=action_spec,
        distribution_class=TanhNormal,
        distribution_kwargs={"low": action_spec.space.low, "high": action_spec.space.high},
        return_log_prob=True,
    )
    critic = ValueOperator(encoder(1), in_keys=["cameras"])
    with torch.no_grad():  # initialise the lazy layers on a fake observation (no server call)
        sample = env.fake_tensordict()
        actor(sample)
        critic(sample)
    return actor, critic


def main() -> None:
    torch.manual_seed(0)
    env = make_env()
    env.set_seed(0)
    actor, critic = make_modules(env)
    collector = Collector(
        env,
        actor,
        frames_per_batch=FRAMES_PER_BATCH,
        total_frames=TOTAL_FRAMES,
        auto_register_policy_transforms=False,  # a feed-forward policy needs no InitTracker
    )
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(FRAMES_PER_BATCH),
        sampler=SamplerWithoutReplacement(),
        batch_size=MINI_BATCH,
    )
    advantage = GAE(gamma=0.99, lmbda=0.95, value_network=critic, average_gae=False)
    loss = ClipPPOLoss(
        actor, critic, clip_epsilon=0.2, entropy_coeff=1e-3, normalize_advantage=True
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=LR)
    logger = get_logger("csv", logger_name=OUTPUT, experiment_name="ppo")

    frames = 0
    try:
        for batch in collector:
            frames += batch.numel()
            done = batch["next", "done"]
            if done.any():
                returns = batch["next", "episode_reward"][done]
                logger.log_scalar("train/episode_return", returns.mean().item(), step=frames)
            for _ in range(EPOCHS):
                with torch.no_grad():
                    advantage(batch)
                buffer.extend(batch.reshape(-1))
                for minibatch in buffer:
                    losses = loss(minibatch)
                    total = (
                        losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
                    )
                    optimizer.zero_grad()
                    total.backward()
                    torch.nn.utils.clip_grad_norm_(loss.parameters(), 1.0)
                    optimizer.step()
            logger.log_scalar("train/loss", total.item(), step=frames)
            collector.update_policy_weights_()
            print(f"{frames} frames, last loss {total.item():.3f}")
    finally:
        collector.shutdown()
        env.close()
    print(f"curves in {OUTPUT}/ppo")


if __name__ == "__main__":
    main()
