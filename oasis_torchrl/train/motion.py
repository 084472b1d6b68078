"""``train motion``: the frames-only reward's network fitted to the embedded world's ground truth.

Data: rounds of ``num_envs`` episodes on the embedded server, each round driven by the next of
``drivers`` (the autopilot and its late-reacting variant for close passes, constant throttles that
crash, weaving, a car held still, ...) through scenes drawn from ``prompts``, at each of
``render_sizes`` in turn (the env's default size and the hosted model's 768x512). The front frames
travel as the hosted model's VP9 and are decoded to ``image_size``. A collision does not end an
episode here: the car stands still after it, which is what the collided head must recognise.

Labels per chunk, from ground truth: the progress along the road gained during the chunk, whether
a frame of the chunk collided, and the chunks to the next collision (the hazard head's target,
:func:`~oasis_torchrl.models.motion.hazard_loss`). The last rounds (``validation``) are kept out
of training. Config: :class:`~oasis_torchrl.config.reward_networks.MotionTrainConfig`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf
from torch.nn import functional as F
from tqdm import tqdm

from oasis_torchrl.config.reward_networks import MotionTrainConfig
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.envs.episodes import episode_prompts
from oasis_torchrl.models.depth import parameter_count
from oasis_torchrl.models.motion import MotionNet, MotionNetConfig, hazard_loss
from oasis_torchrl.protocol import FRONT, HOSTED_FRAME_SIZE
from oasis_torchrl.rewards.base import NoReward
from oasis_torchrl.rewards.motion_net import load_motion_net, save_motion_weights
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.train.driven_rounds import kept_or_driven, split_rounds
from oasis_torchrl.train.motion_checks import check_reward
from oasis_torchrl.train.motion_chunks import UNLABELLED, MotionChunks, chunk_labels
from oasis_torchrl.train.motion_dataset import dataset_motion_chunks, episodes_of

logger = logging.getLogger(__name__)


def motion_env(settings: MotionTrainConfig, render: tuple[int, int]) -> OasisEnv:
    """The embedded-server env of one render size: VP9 decoded to ``image_size``, all 4 frames,
    the expert on (the autopilot drivers need it), collisions not ending episodes."""
    height, width = settings.image_size
    return OasisEnv(
        "local",
        settings.num_envs,
        episode_prompts(settings.prompts),
        server=ServerConfig(width=render[1], height=render[0]),
        frame_size=(height, width),
        frame_format=settings.frame_format,
        all_frames=True,
        expert=True,
        reward=NoReward(),
        terminate_on_collision=False,
        max_steps=settings.steps,
    )


def round_sizes(settings: MotionTrainConfig) -> dict[tuple[int, int], list[int]]:
    """The rounds rendered at each size: every ``hosted_every``-th at the hosted model's.

    Example:
        >>> round_sizes(MotionTrainConfig(episodes=32, num_envs=8, hosted_every=2))
        {(64, 96): [0, 2], (512, 768): [1, 3]}
    """
    small = (int(settings.image_size[0]), int(settings.image_size[1]))
    sizes: dict[tuple[int, int], list[int]] = {}
    for index in range(settings.episodes // settings.num_envs):
        hosted = settings.hosted_every and (index + 1) % settings.hosted_every == 0
        sizes.setdefault(HOSTED_FRAME_SIZE if hosted else small, []).append(index)
    return sizes


def collect_motion_chunks(settings: MotionTrainConfig) -> MotionChunks:
    """Drive the rounds (drivers in turn, every ``hosted_every``-th at the hosted size) and label
    every chunk."""
    parts = []
    for size_index, (render, rounds) in enumerate(round_sizes(settings).items()):
        env = motion_env(settings, render)
        try:
            env.set_seed(settings.seed + size_index)
            for index in tqdm(rounds, desc=f"driving at {render}", disable=not settings.progress):
                driver = load_driver(settings.drivers[index % len(settings.drivers)])
                rollout = env.rollout(settings.steps, driver, break_when_any_done=False)
                parts.append(_labelled(rollout, index, settings.horizon))
        finally:
            env.close()
    return MotionChunks.concat(parts)


def _labelled(rollout: torch.Tensor, round_index: int, horizon: int) -> MotionChunks:
    step = rollout["next"]
    truth = step["truth"]
    gained, hit, time_to = chunk_labels(truth["progress"], truth["collided"], horizon)
    return MotionChunks(
        frames=step["pixels", FRONT].flatten(0, 1).contiguous(),
        actions=rollout["action"].flatten(0, 1).float(),
        progress=gained.flatten().float(),
        collided=hit.flatten(),
        time_to=time_to.flatten().long(),
        rounds=torch.full((gained.numel(),), round_index),
    )


def motion_losses(
    net: MotionNet, batch: MotionChunks, collided_weight: float = 1.0
) -> dict[str, torch.Tensor]:
    """The three heads' losses on ``batch``: Huber on progress (m), cross-entropy on collided,
    the hazard likelihood on the chunks before a collision."""
    out = net(batch.frames, batch.actions)
    known = batch.progress.isfinite()  # a person's recordings label crashes, not progress
    losses = {
        "progress": F.smooth_l1_loss(out.progress[known], batch.progress[known], beta=0.25)
        if known.any()
        else out.progress.sum() * 0.0,
        "collided": collided_weight
        * F.binary_cross_entropy_with_logits(out.collided, batch.collided.float()),
    }
    before = batch.time_to != UNLABELLED
    zero = out.ahead.sum() * 0.0
    losses["ahead"] = (
        hazard_loss(out.ahead[before], batch.time_to[before]) if before.any() else zero
    )
    return losses


@dataclass
class MotionTrainResult:
    """The weights file written, the chunks trained on, the last validation losses and (trained
    from a dataset) the reward's checks on its held-out episodes
    (:func:`~oasis_torchrl.train.motion_checks.check_reward`)."""

    path: Path
    chunks: int
    validation: dict[str, float]
    checks: dict[str, float] = field(default_factory=dict)


def _mirrored(batch: MotionChunks, generator: torch.Generator) -> MotionChunks:
    """About half the rows mirrored left to right (the steering flips with them)."""
    flip = torch.rand(len(batch), generator=generator) < 0.5
    frames = torch.where(flip.view(-1, 1, 1, 1, 1), batch.frames.flip(3), batch.frames)
    steering = torch.where(flip.view(-1, 1), -batch.actions[..., 1], batch.actions[..., 1])
    actions = torch.stack([batch.actions[..., 0], steering], dim=-1)
    return dataclasses.replace(batch, frames=frames, actions=actions)


def evaluate_losses(net: MotionNet, data: MotionChunks, batch_size: int = 256) -> dict[str, float]:
    """Mean losses of ``net`` on ``data`` (evaluation mode, no gradients)."""
    net.eval()
    sums: dict[str, float] = {}
    with torch.no_grad():
        for start in range(0, len(data), batch_size):
            rows = torch.arange(start, min(start + batch_size, len(data)))
            for name, value in motion_losses(net, data.select(rows)).items():
                sums[name] = sums.get(name, 0.0) + value.item() * len(rows)
    return {name: total / len(data) for name, total in sums.items()}


def initial_net(settings: MotionTrainConfig) -> MotionNet:
    """The network training starts from: the weights ``init_from`` names, else a fresh one.

    Example:
        >>> initial_net(MotionTrainConfig(init_from="small")).cfg.horizon
        5
    """
    if settings.init_from is not None:
        net = load_motion_net(settings.init_from)
        if net.cfg.horizon != settings.horizon:
            raise ValueError(
                f"init_from {settings.init_from!r} predicts {net.cfg.horizon} chunks ahead, "
                f"horizon is {settings.horizon}: set horizon={net.cfg.horizon}"
            )
        return net.train()
    return MotionNet(
        MotionNetConfig(
            image_size=tuple(settings.image_size),
            channels=tuple(settings.channels),
            horizon=settings.horizon,
        )
    )


def train_motion(cfg: MotionTrainConfig | DictConfig) -> MotionTrainResult:
    """Drive (or read) the chunks, fit :class:`~oasis_torchrl.models.motion.MotionNet`, write it.

    Example:
        >>> import tempfile
        >>> result = train_motion(MotionTrainConfig(episodes=2, num_envs=1, steps=6, epochs=1,
        ...     hosted_every=0, drivers=["constant:throttle=1.0"], validation=0.5,
        ...     output=f"{tempfile.mkdtemp()}/m.pt", progress=False))
        >>> result.chunks, sorted(result.validation)
        (6, ['ahead', 'collided', 'progress'])
    """
    settings = cfg if isinstance(cfg, MotionTrainConfig) else OmegaConf.to_object(cfg)
    started = time.monotonic()
    torch.manual_seed(settings.seed)
    data = kept_or_driven(settings.chunks_file, MotionChunks.load, lambda: _chunks(settings))
    driven = time.monotonic() - started
    train, held = split_rounds(data, settings.validation)
    net = initial_net(settings)
    optimizer = torch.optim.AdamW(net.parameters(), settings.lr, weight_decay=settings.weight_decay)
    steps = settings.epochs * math.ceil(len(train) / settings.batch_size)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, max(steps, 1))
    generator = torch.Generator().manual_seed(settings.seed)
    logger.info(
        "motion network: %d parameters, %d training chunks", parameter_count(net), len(train)
    )
    bar = tqdm(total=steps, desc="training", disable=not settings.progress)
    for _ in range(settings.epochs):
        net.train()
        order = torch.randperm(len(train), generator=generator)
        for start in range(0, len(train), settings.batch_size):
            rows = order[start : start + settings.batch_size]
            batch = _mirrored(train.select(rows), generator)
            loss = sum(motion_losses(net, batch).values())
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            schedule.step()
            bar.update()
            bar.set_postfix(loss=f"{loss.item():.3f}")
    bar.close()
    validation = evaluate_losses(net, held) if held is not None else {}
    checks = check_reward(net, episodes_of(held)) if settings.dataset and held else {}
    path = save_motion_weights(
        net,
        settings.output,
        meta={
            "settings": dataclasses.asdict(settings),
            "chunks": len(train),
            "validation": validation,
            "checks": checks,
            "seconds_driving": round(driven, 1),
            "seconds_total": round(time.monotonic() - started, 1),
        },
    )
    logger.info("validation losses %s; wrote %s", validation, path)
    if checks:
        logger.info("the reward on the dataset's held-out episodes: %s", checks)
    return MotionTrainResult(path, len(train), validation, checks)


def _chunks(settings: MotionTrainConfig) -> MotionChunks:
    """The chunks of ``settings.dataset``, else the driven rounds'."""
    if settings.dataset:
        size = (int(settings.image_size[0]), int(settings.image_size[1]))
        return dataset_motion_chunks(
            settings.dataset, size, settings.horizon, progress=settings.progress
        )
    return collect_motion_chunks(settings)
