"""Settings of the frames-only rewards' networks, trained on the embedded world's frames:
``train motion`` (the motion reward's network, :mod:`oasis_torchrl.train.motion`) and ``train
depth`` (the reference reward's small depth network, :mod:`oasis_torchrl.train.depth`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from oasis_torchrl.config.scenes import HELD_OUT_SCENES
from oasis_torchrl.options import option


@dataclass
class WorldFramesTrainConfig:
    """What ``train motion`` and ``train depth`` share: frames of the embedded world, as they
    travel and at the size the network sees them, and AdamW from a seed. Each adds who drives
    and how much (:func:`check_rounds`) and its network's settings."""

    image_size: list[int] = option(
        default_factory=lambda: [64, 96],
        help="[height, width] the frames are decoded to and the network is trained at",
    )
    frame_format: str = option(
        "vp9", help="how frames travel: vp9 (the hosted model's compression) | raw | jpeg"
    )
    lr: float = option(2.0e-3, help="AdamW's learning rate (cosine-annealed to 0)", gt=0.0)
    weight_decay: float = option(1.0e-4, help="AdamW's weight decay")
    seed: int = option(0, help="seed of the episodes, the initialisation and the batches")
    progress: bool = option(True, help="tqdm progress bars")

    def __post_init__(self) -> None:
        if len(self.image_size) != 2 or min(self.image_size) <= 0:
            raise ValueError(f"image_size must be [height, width], got {list(self.image_size)}")


def check_rounds(
    episodes: int, num_envs: int, drivers: Sequence[str], prompts: Sequence[str]
) -> None:
    """Refuse episodes that are not whole rounds of ``num_envs``, or no driver or prompt.

    Example:
        >>> check_rounds(32, 8, ["autopilot"], ["urban"])
        >>> check_rounds(30, 8, ["autopilot"], ["urban"])
        Traceback (most recent call last):
        ...
        ValueError: episodes (30) must be a multiple of num_envs (8)
    """
    if episodes % num_envs:
        raise ValueError(f"episodes ({episodes}) must be a multiple of num_envs ({num_envs})")
    if not drivers or not prompts:
        raise ValueError("drivers and prompts must each name at least one")


# -- the frames-only reward's motion network -----------------------------------------------

MOTION_TRAINING_PROMPTS = (
    "urban street",
    "city street at night",
    "urban street at sunset in the rain",
    "city street in the snow",
    "foggy urban street at night",
    "rainy city street",
    "highway",
    "highway at sunset",
    "snowy highway",
    "foggy highway at sunset",
    "rural road",
    "rural road at night",
    "rural road at sunset in the fog",
    "rainy rural road",
    "snowy rural road at night",
    "highway at night",
)
"""The scenes ``train motion`` draws from: every layout, lighting and weather, none of
:data:`~oasis_torchrl.config.scenes.HELD_OUT_SCENES`, where it is judged."""


@dataclass
class MotionTrainConfig(WorldFramesTrainConfig):
    """``oasis-torchrl train motion``: the frames-only reward's network
    (oasis_torchrl.models.motion) on the embedded world's front frames, labelled by its ground
    truth (progress, collisions)."""

    hosted_every: int = option(
        7,
        help="every this many rounds, one is rendered at the hosted model's 768x512 (decoded "
        "down to image_size); the others at image_size (0: none)",
        ge=0,
    )
    channels: list[int] = option(
        default_factory=lambda: [16, 32, 48, 64], help="widths of the network's levels"
    )
    horizon: int = option(5, help="chunks ahead the collision-ahead head predicts", ge=1)
    prompts: list[str] = option(
        default_factory=lambda: list(MOTION_TRAINING_PROMPTS), help="scenes, one drawn per episode"
    )
    drivers: list[str] = option(
        default_factory=lambda: [
            "autopilot",
            "constant:throttle=1.0,steering=0.0",
            "scripted:throttle=sine:0.7:90:0.3,steering=sine:0.4:60",
            "scripted:throttle=1.0,steering=weave:0.088:20:100",
            "constant:throttle=0.5,steering=0.0",
            "scripted:throttle=sine:1.0:70,steering=sine:0.8:30",
            "constant:throttle=0.0,steering=0.0",
            "scripted:throttle=0.75,steering=sine:0.15:120",
        ],
        help="who drives (oasis_torchrl.drivers grammar), one per round of num_envs episodes, "
        "in turn",
    )
    num_envs: int = option(8, help="episodes driven at once (one round)", ge=1)
    episodes: int = option(256, help="episodes driven (a multiple of num_envs)", ge=1)
    steps: int = option(60, help="chunks per episode (a collision does not end it)", ge=1)
    epochs: int = option(8, help="passes over the chunks", ge=1)
    batch_size: int = option(64, help="chunks per step", ge=1)
    validation: float = option(
        0.125,
        help="share of the episodes (whole rounds) kept out of training to report losses",
        ge=0.0,
        lt=1.0,
    )
    chunks_file: str | None = option(
        None,
        help="keep the driven chunks here: read when the file exists (no driving), else written "
        "after driving (null: not kept)",
    )
    init_from: str | None = option(
        None,
        help="fine-tune these weights (small: the shipped ones, or a weights file; their shape "
        "wins over channels) instead of starting afresh",
    )
    dataset: str | None = option(
        None,
        help="train on this LeRobot dataset's episodes instead of driving: its crash marks "
        "(next.crash: the drive page's C key, or the world's collisions) label the collided and "
        "collision-ahead heads; it holds no progress, so the progress head keeps init_from's "
        "(use init_from=small); the reward's checks are printed on the held-out episodes",
    )
    output: str = option("outputs/motion/motion_small.pt", help="the weights file written")

    def __post_init__(self) -> None:
        super().__post_init__()
        check_rounds(self.episodes, self.num_envs, self.drivers, self.prompts)
        judged = sorted(set(self.prompts) & set(HELD_OUT_SCENES))
        if judged:
            raise ValueError(f"prompts must not hold the held-out scenes {judged}")


# -- the small depth network -------------------------------------------------------------------

DEPTH_TRAINING_PROMPTS = (
    "urban street",
    "city street at night",
    "urban street at sunset in the rain",
    "city street in the snow",
    "foggy urban street at night",
    "rainy city street",
    "highway",
    "highway at sunset",
    "highway at night in the rain",
    "snowy highway",
    "foggy highway at sunset",
    "rural road",
    "rural road at night",
    "rural road at sunset in the fog",
    "rainy rural road",
    "snowy rural road at night",
)
"""The scenes ``train depth`` draws from: every layout, lighting and weather, in combinations
that :data:`DEPTH_HELD_OUT_PROMPTS` does not use."""

DEPTH_HELD_OUT_PROMPTS = (
    "snowy city avenue at sunset",
    "foggy downtown city street",
    "highway in the fog at night",
    "rainy highway in daylight",
    "rural lane in the snow at sunset",
    "foggy rural road",
)
"""Scenes no ``train depth`` run sees by default (new wording and keyword combinations): the
agreement benchmark's."""


@dataclass
class DepthTrainConfig(WorldFramesTrainConfig):
    """``oasis-torchrl train depth``: the small depth network (oasis_torchrl.models.depth) on
    the embedded world's front frames, with the simulator's metric depth as the target."""

    render_scale: int = option(
        2,
        help="the world is rendered at this multiple of image_size; frames are decoded down to "
        "it and the target's nearness averaged down to it",
        ge=1,
    )
    channels: list[int] = option(
        default_factory=lambda: [12, 24, 48, 96], help="widths of the network's levels"
    )
    prompts: list[str] = option(
        default_factory=lambda: list(DEPTH_TRAINING_PROMPTS), help="scenes, one drawn per episode"
    )
    drivers: list[str] = option(
        default_factory=lambda: [
            "autopilot",
            "constant:throttle=0.8,steering=0.0",
            "scripted:throttle=sine:0.4:120:0.5,steering=sine:0.5:50",
            "scripted:throttle=1.0,steering=weave:0.088:20:100",
        ],
        help="who drives (oasis_torchrl.drivers grammar), one per round of num_envs episodes, "
        "in turn",
    )
    num_envs: int = option(4, help="episodes driven at once (one round)", ge=1)
    episodes: int = option(32, help="episodes driven (a multiple of num_envs)", ge=1)
    steps: int = option(40, help="steps per episode (one frame each; a crash starts another)", ge=1)
    epochs: int = option(15, help="passes over the frames", ge=1)
    batch_size: int = option(32, help="frames per step", ge=1)
    near_weight: float = option(
        0.0,
        help="extra weight of near pixels in the loss: 1 + near_weight x the target's min-max "
        "normalised nearness (0: every pixel alike)",
        ge=0.0,
    )
    validation: float = option(
        0.1,
        help="share of the episodes (whole rounds) kept out of training to report a loss",
        ge=0.0,
        lt=1.0,
    )
    frames_file: str | None = option(
        None,
        help="keep the driven frames and their nearness here: read when the file exists (no "
        "driving), else written after driving (null: not kept)",
    )
    output: str = option("outputs/depth/depth_small.pt", help="the weights file written")

    def __post_init__(self) -> None:
        super().__post_init__()
        check_rounds(self.episodes, self.num_envs, self.drivers, self.prompts)
