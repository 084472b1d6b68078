"""Settings of the world-model env a command drives: the ``env`` section of every config."""

from __future__ import annotations

from dataclasses import dataclass

from oasis_torchrl.options import option
from oasis_torchrl.protocol import FPS

LOCAL = "local"
"""``env.endpoint`` of an embedded server started for the env."""
AUTO = "auto"
"""A setting found from the endpoint (:mod:`oasis_torchrl.envs.capabilities`)."""
REWARD_KINDS = (AUTO, "ground_truth", "motion", "depth")


@dataclass
class EmbeddedServerConfig:
    """The embedded server an ``endpoint: local`` env starts (other endpoints ignore it)."""

    width: int = option(96, help="frame width of the embedded server")
    height: int = option(64, help="frame height of the embedded server")
    fps: float = option(FPS, help="frame rate of the embedded world (its time step is 1/fps)")
    hosted: bool = option(
        False,
        help="hosted-like: the server sends only what the hosted service sends (VP9 frames; no "
        "ground truth, expert or depth; seeds ignored), at the size above",
    )


@dataclass
class RewardConfig:
    """The reward: ground truth where the endpoint sends it, else the motion reward on the
    front frames (progress seen, crashes seen)."""

    kind: str = option(
        AUTO,
        help="auto (ground_truth where the endpoint sends it, else motion) | ground_truth "
        "(embedded server) | motion (progress and crashes seen in the frames) | depth (the "
        "reference's depth-collision reward, for comparison)",
        choices=REWARD_KINDS,
    )
    motion_model: str = option(
        "small",
        help="the motion reward's network: small (the shipped one) or a weights file written "
        "by 'oasis-torchrl train motion'",
    )
    depth_model: str = option(
        "small",
        help="depth model of the depth reward: small (the shipped network, offline) or a "
        "transformers model id, e.g. depth-anything/Depth-Anything-V2-Small-hf (the reference's)",
    )
    progress_scale: float = option(0.1, help="reward per metre along the road")
    collision_penalty: float = option(
        2.0,
        help="penalty of a collision, on top of the progress it forgoes (a large one makes PPO "
        "drive slowly instead of steering around obstacles)",
    )
    swing_weight: float = option(
        0.1,
        help="motion reward: cost per unit of the mean squared change of the action from one "
        "action to the next (a policy swinging the steering is seen moving farther than it "
        "drives; 0: off)",
        ge=0.0,
    )
    lane_penalty: float = option(0.01, help="penalty per metre off the lane centre")
    clearance_weight: float = option(
        0.0, help="cost of an obstacle ahead (ClearanceShaping; 0: off)"
    )
    clearance_horizon: float = option(25.0, help="metres ahead from which an obstacle costs")


@dataclass
class EnvConfig:
    """The world-model env: endpoint, prompts, batch, episode length, image size, reward."""

    endpoint: str = option(LOCAL, help="'local' (an embedded server) or an A2V endpoint URL")
    prompts: list[str] = option(
        default_factory=lambda: ["urban"],
        help="episode prompts: one for every episode, or several drawn from per episode",
    )
    num_envs: int = option(8, help="concurrent world-model sessions (rows of the batch)", ge=1)
    max_steps: int = option(150, help="chunks per episode (150 = 30 s of world time)", ge=1)
    image_size: tuple[int, int] | None = option(
        (64, 96),
        help="[height, width] the frames are decoded to, the policy's input size (null: the "
        "server's size)",
    )
    front_crop: float | None = option(
        None,
        help="add a narrow forward camera, front_crop: the centre of the front camera, this "
        "fraction of its height and width, cut from the front frame at the server's full size "
        "and resized to image_size (an embedded server then renders large enough for it); "
        "null: off",
        gt=0.0,
        le=1.0,
    )
    server: EmbeddedServerConfig = option(
        default_factory=EmbeddedServerConfig, help="the embedded server of endpoint 'local'"
    )
    reward: RewardConfig = option(default_factory=RewardConfig, help="the reward")

    def __post_init__(self) -> None:
        if not self.endpoint:
            raise ValueError(
                "env.endpoint must be 'local' or an A2V endpoint URL, got an empty one (is "
                "DECART_ROBOTICS_ENDPOINT set but empty?)"
            )
        if not self.prompts:
            raise ValueError("env.prompts must hold at least one prompt")
