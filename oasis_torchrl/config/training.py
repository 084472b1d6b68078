"""Settings of the training recipes: PPO in the world model and behaviour cloning (BC).

Each recipe's settings split in two: what a training stage needs (``PPOSettings``,
``BCSettings``: network, optimiser, loss, schedule) and what a stand-alone run adds (the env,
the evaluation and the run section, :class:`~oasis_torchrl.config.run.TrainingRun`:
``PPOConfig``, ``BCConfig``). Both recipes' optimiser sections are one description,
:class:`OptimiserConfig` (PPO's adds its own rates and schedule). The main job
(:class:`~oasis_torchrl.config.pipeline.DemoConfig`) nests the stage settings and shares one
env and one evaluation between its stages.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from oasis_torchrl.config.env import EnvConfig, RewardConfig
from oasis_torchrl.config.evaluation import EvaluationConfig
from oasis_torchrl.config.ray import RayCollectionConfig
from oasis_torchrl.config.run import TrainingRun, output_dir_option
from oasis_torchrl.options import option

LOGGER_BACKENDS = ("csv", "tensorboard")


@dataclass
class LoggerConfig:
    """Where training curves go (a TorchRL logger)."""

    backend: str = option("csv", help="csv | tensorboard", choices=LOGGER_BACKENDS)
    exp_name: str = option("ppo", help="experiment name (the logger's folder)")


# -- the driving network -----------------------------------------------------------------------


@dataclass
class NetworkArchitectureConfig:
    """The driving network's shape, shared by PPO's fresh network and BC's policy: the one
    definition of these defaults, which oasis_torchrl.models.DrivingNetConfig takes too."""

    shared_encoder: bool = option(True, help="one encoder for every camera")
    encoder_channels: list[int] = option(
        default_factory=lambda: [24, 48, 64], help="channels of the three convolutions"
    )
    encoder_strides: list[int] = option(
        default_factory=lambda: [4, 2, 1],
        help="strides of the three convolutions (4: a 4x4 patch, 1 or 2: 3x3); [2, 2, 2] keeps "
        "twice the resolution in the first two layers, at a higher cost per step",
    )
    pool_grid: list[int] = option(
        default_factory=lambda: [4, 6], help="[rows, cols] the last feature map is pooled to"
    )
    camera_features: int = option(128, help="features per camera")
    hidden_dim: int = option(256, help="width of the actor MLP (and of PPO's value MLP)")
    head: str = option(
        "mixture",
        help="action head: mixture (a mixture of tanh-normals over the chunk, commits to one "
        "manoeuvre) | tanh_normal (one tanh-normal, unimodal)",
    )
    components: int = option(3, help="mixture components")


# -- PPO ---------------------------------------------------------------------------------------


@dataclass
class NetworkConfig(NetworkArchitectureConfig):
    """The driving network of a fresh PPO run (ignored on a warm start)."""

    use_state: bool = option(True, help="the previous action as an input")
    init_action: list[float] = option(
        default_factory=lambda: [0.5, 0.0],
        help="a fresh actor's mean [throttle, steering]: drive, don't stand",
    )
    init_spread: list[float] = option(
        default_factory=lambda: [0.0, 0.3],
        help="a fresh mixture's components spread this far around init_action (keep, left, "
        "right), the middle one most likely",
    )
    # Steering explores as widely as throttle from scratch: with a smaller scale PPO found its
    # first lane changes later, and the learned scale shrinks it anyway
    # (docs/experiments/2026-11-28-ppo-from-scratch.md). A warm start keeps its own
    # (`warm_start_scale`).
    init_scale: list[float] = option(
        default_factory=lambda: [0.5, 0.5],
        help="initial scale (before the tanh) of [throttle, steering] of a fresh network",
    )


@dataclass
class CollectorConfig:
    """How much experience: TorchRL counts one env step (one 4-frame chunk) as a frame."""

    frames_per_batch: int = option(512, help="env steps per PPO iteration (all rows together)")
    total_frames: int = option(20480, help="env steps in the whole run")


AUX_COEFF = 1.0
"""``loss.aux_coeff`` where the endpoint sends ground truth and the setting is null."""


@dataclass
class LossConfig:
    """ClipPPOLoss and GAE, plus the auxiliary ground-truth head."""

    gamma: float = option(0.98, help="discount")
    lmbda: float = option(0.95, help="GAE lambda")
    clip_epsilon: float = option(0.2, help="PPO clip range")
    entropy_coeff: float = option(0.001, help="entropy bonus")
    critic_coeff: float = option(0.5, help="value loss weight")
    loss_critic_type: str = option("smooth_l1", help="value loss: smooth_l1 | l2 | l1")
    critic_warmup_iters: int = option(
        0, help="first iterations train the critic only (use after a warm start)"
    )
    aux_coeff: float | None = option(
        None,
        help="the camera features also learn to predict the privileged state (MSE, a "
        f"training-only head; needs ground truth; 0: off; null: {AUX_COEFF} where the endpoint "
        "sends ground truth, else 0)",
    )


def check_holds_minibatch(name: str, rows: int, mini_batch_size: int) -> None:
    """Refuse a ring of ``rows`` (0: off) that cannot hold one minibatch (its section's
    ``mini_batch_size``, which must be positive).

    Example:
        >>> check_holds_minibatch("warmup.frames", 0, 64)  # off
        >>> check_holds_minibatch("warmup.frames", 32, 64)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: warmup.frames (32) must hold at least one minibatch ...
    """
    if rows and not rows >= mini_batch_size > 0:
        section = name.split(".")[0]
        raise ValueError(
            f"{name} ({rows}) must hold at least one minibatch "
            f"({section}.mini_batch_size {mini_batch_size}, > 0)"
        )


@dataclass
class AuxReplayConfig:
    """Past observations replayed for the auxiliary loss (oasis_torchrl.train.aux_replay)."""

    capacity: int = option(
        0,
        help="rows of past observations (frames as uint8, ~110 KB a row at 64x96) and their "
        "privileged state kept for the auxiliary loss (0: off; needs loss.aux_coeff > 0)",
        ge=0,
    )
    steps: int = option(16, help="auxiliary-only minibatches after each PPO update", ge=0)
    mini_batch_size: int = option(128, help="rows per replayed minibatch")

    def __post_init__(self) -> None:
        check_holds_minibatch("aux_replay.capacity", self.capacity, self.mini_batch_size)


@dataclass
class PerceptionWarmupConfig:
    """The encoder fitted to the privileged state of the run's first env steps, before PPO's
    first update (oasis_torchrl.train.perception_warmup)."""

    frames: int = option(
        0,
        help="env steps driven for the warm-up (warmup.driver), counted in "
        "collector.total_frames (0: off; needs loss.aux_coeff > 0)",
        ge=0,
    )
    driver: str | None = option(
        None,
        help="who drives them: null, the policy itself (its initial exploration), or a driver "
        "that needs no expert, e.g. 'constant:throttle=1.0,steering=0.0' (oasis_torchrl.drivers)",
    )
    steps: int = option(6000, help="auxiliary-only minibatches fitted on them", ge=0)
    mini_batch_size: int = option(64, help="rows per minibatch")
    lr: float = option(1.0e-3, help="Adam's learning rate for the warm-up", gt=0.0)

    def __post_init__(self) -> None:
        check_holds_minibatch("warmup.frames", self.frames, self.mini_batch_size)


@dataclass
class OptimiserConfig:
    """The optimiser's settings both trainers have (BC: AdamW, PPO: Adam); the defaults are
    behaviour cloning's, PPO's section sets its own (:func:`ppo_optimiser`)."""

    lr: float = option(
        1.0e-3, help="learning rate (PPO: of the actor and encoder; critic_lr, scale_lr: the rest)"
    )
    weight_decay: float = option(
        1.0e-4, help="weight decay (BC: AdamW's, decoupled; PPO: Adam's, an L2 penalty)"
    )
    max_grad_norm: float = option(10.0, help="gradient clipping: the gradient's largest norm")


@dataclass
class OptimConfig(OptimiserConfig):
    """Adam over the actor, encoder and critic: the shared optimiser settings at PPO's values
    (:func:`ppo_optimiser`), its own rates and its schedule."""

    critic_lr: float | None = option(
        1.0e-3, help="learning rate of the critic head (null: lr); a fresh critic needs the pace"
    )
    scale_lr: float | None = option(
        1.0e-2,
        help="learning rate of the action scale (null: lr); its gradient is weak and noisy",
    )
    pool_scale: bool = option(
        True,
        help="learn one action scale per action number (its gradient pooled over the chunk and "
        "the components) instead of one per chunk entry",
    )
    epochs: int = option(4, help="passes over each batch")
    mini_batch_size: int = option(128, help="env steps per minibatch")
    anneal_lr: bool = option(True, help="decay the learning rates linearly over the run")
    # A schedule longer than the run makes a shorter run the exact start of a longer one (the
    # learning benchmark rates the first 102,400 env steps of a 204,800-env-step schedule),
    # which a resume with the larger budget then completes.
    anneal_frames: int | None = option(
        None,
        help="env steps the learning rates decay over (null: collector.total_frames; larger: "
        "the run stops part-way through the schedule)",
        gt=0,
    )


def ppo_optimiser() -> OptimConfig:
    """PPO's optimiser section: a tenth of behaviour cloning's learning rate for the actor and
    encoder, no weight decay, tight clipping.

    Example:
        >>> optim = ppo_optimiser()
        >>> optim.lr, optim.weight_decay, optim.max_grad_norm
        (0.0003, 0.0, 0.5)
    """
    return OptimConfig(lr=3.0e-4, weight_decay=0.0, max_grad_norm=0.5)


@dataclass
class PPOEvaluationConfig(EvaluationConfig):
    """PPO's periodic evaluations (and the final one, on ``seeds``)."""

    every: int = option(10, help="iterations between evaluations (0: only at the end)")
    selection_seeds: list[int] | None = option(
        None,
        help="periodic evaluations on these seeds pick the policy kept (checkpoints/best.pt), "
        "evaluated on `seeds` at the end; a warm start is rated first, so fine-tuning keeps "
        "it unless a later policy beats it",
    )
    selection_margin: float = option(
        0.0,
        help="standard errors of the paired per-episode difference by which a policy must beat "
        "the kept one on the selection seeds to replace it (0: any higher mean distance)",
        ge=0.0,
    )
    final: bool = option(
        True,
        help="evaluate the kept policy on `seeds` at the end (the main job's own comparison "
        "does, so its PPO stage does not)",
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.selection_seeds is not None and not self.selection_seeds:
            raise ValueError("eval.selection_seeds must be null or a non-empty list of integers")


@dataclass
class CheckpointConfig:
    """When the trainer saves its state."""

    every: int = option(5, help="iterations between checkpoints (the last one is always saved)")
    keep_evaluated: bool = option(
        False, help="also keep each periodically evaluated policy (checkpoints/frames_<N>.pt)"
    )


@dataclass
class PPOSettings:
    """A PPO training stage: network, warm start, collection, loss, optimiser, evaluations."""

    network: NetworkConfig = option(default_factory=NetworkConfig, help="the fresh network")
    privileged_critic: bool | None = option(
        None, help="the critic also reads ground truth (null: where the endpoint sends it)"
    )
    warm_start_scale: list[float] | None = option(
        default_factory=lambda: [0.2, 0.05],
        help="[throttle, steering] action scale after a warm start (null: the source's)",
    )
    collector: CollectorConfig = option(default_factory=CollectorConfig, help="experience")
    loss: LossConfig = option(default_factory=LossConfig, help="the PPO loss")
    aux_replay: AuxReplayConfig = option(
        default_factory=AuxReplayConfig, help="past observations replayed for the auxiliary loss"
    )
    warmup: PerceptionWarmupConfig = option(
        default_factory=PerceptionWarmupConfig,
        help="the encoder fitted to the privileged state of the first env steps",
    )
    optim: OptimConfig = option(default_factory=ppo_optimiser, help="the optimiser")
    eval: PPOEvaluationConfig = option(
        default_factory=PPOEvaluationConfig, help="evaluations during and after training"
    )
    logger: LoggerConfig = option(default_factory=LoggerConfig, help="training curves")
    checkpoint: CheckpointConfig = option(default_factory=CheckpointConfig, help="checkpoints")
    ray: RayCollectionConfig = option(
        default_factory=RayCollectionConfig, help="collection on Ray (off by default)"
    )

    def __post_init__(self) -> None:
        for name, on in (
            ("aux_replay.capacity", self.aux_replay.capacity),
            ("warmup.frames", self.warmup.frames),
        ):
            if on and self.loss.aux_coeff == 0:
                raise ValueError(f"{name} trains the auxiliary loss: set loss.aux_coeff > 0 too")
        if self.warmup.frames and self.warmup.frames >= self.collector.total_frames:
            raise ValueError(
                f"warmup.frames ({self.warmup.frames}) must leave PPO some of "
                f"collector.total_frames ({self.collector.total_frames})"
            )


@dataclass
class PPOConfig(TrainingRun, PPOSettings):
    """``oasis-torchrl train ppo``: TorchRL PPO in the world model (Collector -> GAE ->
    ClipPPOLoss, a TanhNormal actor over a 4-action chunk, a value head on the same encoder)."""

    output_dir: str = output_dir_option("outputs/ppo")
    env: EnvConfig = option(
        default_factory=lambda: EnvConfig(reward=RewardConfig(clearance_weight=0.2)),
        help="the training env",
    )


# -- behaviour cloning -------------------------------------------------------------------------


@dataclass
class BCPolicyConfig(NetworkArchitectureConfig):
    """The cloned policy: the one definition of its settings' defaults, which the LeRobot
    plugin's config (lerobot_policy_oasis.OasisConfig, ``lerobot-train --policy.type=oasis``)
    takes as its own."""

    image_size: list[int] = option(default_factory=lambda: [64, 96], help="[height, width]")
    front_crop: float | None = option(
        None,
        help="the fraction of the front frame the dataset's front_crop camera shows (its "
        "env.front_crop); the policy then reads that camera and its envs get the crop; null: "
        "no crop",
    )
    use_state: bool = option(
        False, help="the previous action as an input (off: a clone would copy it)"
    )
    loss: str = option(
        "nll",
        help="nll (likelihood of the demonstrated chunk) | manoeuvre (likelihood jointly with "
        "its manoeuvre: components left, keep, right)",
    )
    aux_weight: float = option(
        0.0,
        help="weight of the auxiliary loss: predict each frame's privileged state (obstacle "
        "distances, lane offset, speed) from the cameras; needs a dataset that stores it",
    )


@dataclass
class BCTrainConfig:
    """The BC schedule."""

    steps: int = option(3000, help="gradient steps")
    batch_size: int = option(64, help="samples per step")
    num_workers: int = option(0, help="data loader workers")
    shift_pad: int = option(
        4, help="random-shift augmentation of the samples' frames, in pixels (0: off)", ge=0
    )
    log_every: int = option(50, help="steps between logged losses")
    save_every: int = option(
        1000,
        help="also save the policy so far to checkpoints/last every N steps (0: never); policy/ "
        "is written at the end only",
    )


@dataclass
class BCSettings:
    """A behaviour-cloning stage: the policy, its optimiser, its schedule, its logger."""

    RENAMED: ClassVar[dict[str, str]] = {
        "policy.optimizer_lr": "optim.lr",
        "policy.optimizer_weight_decay": "optim.weight_decay",
        "policy.optimizer_grad_clip_norm": "optim.max_grad_norm",
    }
    """The optimiser's settings as configs saved before its own section spelled them."""

    policy: BCPolicyConfig = option(default_factory=BCPolicyConfig, help="the policy")
    optim: OptimiserConfig = option(
        default_factory=OptimiserConfig, help="the optimiser (AdamW, a constant learning rate)"
    )
    train: BCTrainConfig = option(default_factory=BCTrainConfig, help="the schedule")
    logger: LoggerConfig = option(
        default_factory=lambda: LoggerConfig(exp_name="bc"), help="training curves"
    )


@dataclass
class DatasetConfig:
    """The LeRobot dataset to clone (frame rows: one [throttle, steering] per row at 20 fps)."""

    root: str | None = option(None, help="the dataset folder (required)")
    repo_id: str | None = option(None, help="default local/<folder name>")
    episodes: list[int] | None = option(None, help="episode indices, default all")
    cameras: list[str] | None = option(
        None,
        help="the cameras the policy reads, e.g. [left_forward,front,right_forward] (null: all)",
    )
    cache: bool = option(True, help="decode the videos once into memory (much faster epochs)")


@dataclass
class BCConfig(TrainingRun, BCSettings):
    """``oasis-torchrl train bc``: behaviour cloning of the oasis policy on a LeRobot dataset;
    ``<output_dir>/policy`` is a LeRobot policy folder."""

    output_dir: str = output_dir_option("outputs/bc")
    dataset: DatasetConfig = option(default_factory=DatasetConfig, help="the demonstrations")
    eval: EvaluationConfig = option(
        default_factory=EvaluationConfig, help="evaluation after training (episodes 0: none)"
    )
    env: EnvConfig = option(
        default_factory=EnvConfig, help="the evaluation env (the policy's image size is used)"
    )
