"""``train depth``: the small depth network fitted to the embedded world's metric depth.

Data: rounds of ``num_envs`` episodes on the embedded server, each round driven by the next of
``drivers`` (the autopilot, constant throttle, weaving, ...) through scenes drawn from
``prompts``. The world is rendered at ``render_scale`` times ``image_size``; the front frames
travel as the hosted model's VP9 and are decoded down to ``image_size`` (what a policy sees),
while the simulator's metric depth of the same frames becomes nearness ``1 / depth`` (sky 0),
averaged down to the same size. The last rounds (``validation``) are kept out of training.

Training: AdamW with a cosine schedule on :func:`~oasis_torchrl.models.depth.
scale_shift_invariant_loss` (the MiDaS loss on inverse depth), frames mirrored left to right at
random. The weights file (:func:`~oasis_torchrl.rewards.depth_net.save_weights`) carries the
settings and losses. Config: :class:`~oasis_torchrl.config.reward_networks.DepthTrainConfig`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from oasis_torchrl.config.reward_networks import DepthTrainConfig
from oasis_torchrl.drivers import Driver, load_driver
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.envs.episodes import episode_prompts
from oasis_torchrl.models.depth import (
    DepthNet,
    DepthNetConfig,
    nearness_target,
    parameter_count,
    scale_shift_invariant_loss,
)
from oasis_torchrl.rewards.depth_net import save_weights
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.train.driven_rounds import kept_or_driven, split_rounds

logger = logging.getLogger(__name__)

CAMERA = "front"


@dataclass
class DepthFrames:
    """Front frames uint8 ``[M, H, W, 3]``, their nearness float32 ``[M, H, W]`` and the round
    each was driven in ``[M]``."""

    frames: torch.Tensor
    nearness: torch.Tensor
    rounds: torch.Tensor

    def __len__(self) -> int:
        return self.frames.shape[0]

    def select(self, mask: torch.Tensor) -> DepthFrames:
        """The rows where ``mask`` is True."""
        return DepthFrames(self.frames[mask], self.nearness[mask], self.rounds[mask])

    def save(self, path: str | Path) -> None:
        """Write the rows to ``path`` (a torch file; nearness as float16)."""
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        rows = dataclasses.asdict(self) | {"nearness": self.nearness.half()}
        torch.save(rows, path)

    @classmethod
    def load(cls, path: str | Path) -> DepthFrames:
        """The rows :meth:`save` wrote to ``path``.

        Example:
            >>> import tempfile
            >>> path = f"{tempfile.mkdtemp()}/frames.pt"
            >>> DepthFrames(torch.zeros(2, 1, 1, 3), torch.ones(2, 1, 1), torch.zeros(2)).save(path)
            >>> DepthFrames.load(path).nearness.dtype
            torch.float32
        """
        rows = torch.load(path, weights_only=True)
        return cls(rows["frames"], rows["nearness"].float(), rows["rounds"])


@dataclass
class DepthTrainResult:
    """The weights file written and the last epoch's losses (validation: None without it)."""

    path: Path
    frames: int
    train_loss: float
    validation_loss: float | None


def as_settings(cfg: DepthTrainConfig | DictConfig) -> DepthTrainConfig:
    """The settings as their dataclass (a loaded config is converted; its checks run again).

    Example:
        >>> as_settings(DepthTrainConfig(epochs=3)).epochs
        3
    """
    if isinstance(cfg, DepthTrainConfig):
        return cfg
    return OmegaConf.to_object(cfg)


def depth_env(settings: DepthTrainConfig, drivers: list[Driver]) -> OasisEnv:
    """The embedded-server env the frames and depth come from (its front camera's depth on,
    the expert on if a driver needs it)."""
    height, width = settings.image_size
    scale = settings.render_scale
    return OasisEnv(
        "local",
        settings.num_envs,
        episode_prompts(settings.prompts),
        server=ServerConfig(width=width * scale, height=height * scale),
        frame_size=(height, width),
        frame_format=settings.frame_format,
        expert=any(driver.needs_expert for driver in drivers),
        depth_cameras=(CAMERA,),
        max_steps=settings.steps,
    )


def collect_depth_frames(settings: DepthTrainConfig) -> DepthFrames:
    """Drive ``episodes`` episodes (rounds of ``num_envs``, one driver per round in turn) and
    keep every step's front frame and nearness."""
    drivers = [load_driver(spec) for spec in settings.drivers]
    rounds = settings.episodes // settings.num_envs
    env = depth_env(settings, drivers)
    frames, nearness, round_ids = [], [], []
    try:
        env.set_seed(settings.seed)
        for index in tqdm(range(rounds), desc="driving", disable=not settings.progress):
            driver = drivers[index % len(drivers)]
            rollout = env.rollout(settings.steps, driver, break_when_any_done=False)
            step = rollout["next"]
            frames.append(step["pixels", CAMERA].flatten(0, 1))
            depth = step["depth", CAMERA].flatten(0, 1)
            nearness.append(nearness_target(depth, settings.render_scale))
            round_ids.append(torch.full((depth.shape[0],), index))
    finally:
        env.close()
    return DepthFrames(torch.cat(frames), torch.cat(nearness), torch.cat(round_ids))


def batches(
    data: DepthFrames, batch_size: int, generator: torch.Generator, mirror: bool = True
) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
    """Shuffled ``(frames, nearness)`` batches of one epoch, about half mirrored left to right.

    Example:
        >>> data = DepthFrames(torch.zeros(5, 2, 2, 3), torch.zeros(5, 2, 2), torch.zeros(5))
        >>> [f.shape[0] for f, _ in batches(data, 2, torch.Generator().manual_seed(0))]
        [2, 2, 1]
    """
    order = torch.randperm(len(data), generator=generator)
    for start in range(0, len(data), batch_size):
        rows = order[start : start + batch_size]
        frames, nearness = data.frames[rows], data.nearness[rows]
        if mirror:
            flip = torch.rand(len(rows), generator=generator) < 0.5
            frames = torch.where(flip.view(-1, 1, 1, 1), frames.flip(2), frames)
            nearness = torch.where(flip.view(-1, 1, 1), nearness.flip(2), nearness)
        yield frames, nearness


def evaluate_loss(net: DepthNet, data: DepthFrames, batch_size: int = 64) -> float:
    """Mean :func:`scale_shift_invariant_loss` of ``net`` over ``data`` (eval mode)."""
    net.eval()
    total = 0.0
    with torch.inference_mode():
        for start in range(0, len(data), batch_size):
            frames = data.frames[start : start + batch_size]
            loss = scale_shift_invariant_loss(
                net(frames), data.nearness[start : start + batch_size]
            )
            total += loss.item() * frames.shape[0]
    return total / len(data)


def fit(
    net: DepthNet,
    data: DepthFrames,
    *,
    epochs: int,
    batch_size: int,
    lr: float,
    weight_decay: float = 0.0,
    near_weight: float = 0.0,
    seed: int = 0,
    progress: bool = False,
) -> list[float]:
    """Train ``net`` on ``data``; the mean training loss of each epoch."""
    generator = torch.Generator().manual_seed(seed)
    optimizer = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=weight_decay)
    steps = epochs * math.ceil(len(data) / batch_size)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, steps)
    losses = []
    bar = tqdm(range(epochs), desc="training", disable=not progress)
    for _ in bar:
        net.train()
        total = 0.0
        for frames, nearness in batches(data, batch_size, generator):
            loss = scale_shift_invariant_loss(net(frames), nearness, near_weight)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            schedule.step()
            total += loss.item() * frames.shape[0]
        losses.append(total / len(data))
        bar.set_postfix(loss=f"{losses[-1]:.4f}")
    return losses


def train_depth(cfg: DepthTrainConfig | DictConfig) -> DepthTrainResult:
    """Collect frames and depth, train the network, write the weights file (``output``)."""
    settings = as_settings(cfg)
    started = time.perf_counter()
    data = kept_or_driven(
        settings.frames_file, DepthFrames.load, lambda: collect_depth_frames(settings)
    )
    collected = time.perf_counter()
    train, held = split_rounds(data, settings.validation)
    logger.info(
        "collected %d frames (%d for training) in %.0f s",
        len(data),
        len(train),
        collected - started,
    )
    torch.manual_seed(settings.seed)
    net = DepthNet(DepthNetConfig(tuple(settings.channels)))
    logger.info("training a depth network of %d parameters", parameter_count(net))
    losses = fit(
        net,
        train,
        epochs=settings.epochs,
        batch_size=settings.batch_size,
        lr=settings.lr,
        weight_decay=settings.weight_decay,
        near_weight=settings.near_weight,
        seed=settings.seed,
        progress=settings.progress,
    )
    validation_loss = evaluate_loss(net, held) if held is not None else None
    finished = time.perf_counter()
    meta = {
        # Where files were is of no use to a reader of the weights (and names this machine).
        "settings": dataclasses.asdict(settings) | {"output": None, "frames_file": None},
        "frames": len(data),
        "train_loss": losses[-1],
        "validation_loss": validation_loss,
        "collect_seconds": round(collected - started, 1),
        "train_seconds": round(finished - collected, 1),
    }
    path = save_weights(settings.output, net, tuple(settings.image_size), meta)
    logger.info(
        "depth network: loss %.4f (validation %s) in %.0f s; weights %s",
        losses[-1],
        "n/a" if validation_loss is None else f"{validation_loss:.4f}",
        finished - started,
        path,
    )
    return DepthTrainResult(path, len(data), losses[-1], validation_loss)
