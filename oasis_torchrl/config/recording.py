"""Settings of the dataset-writing commands: ``record`` (drive the world model) and
``import-recordings`` (human recordings), which share the output settings."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import ClassVar

from oasis_torchrl.config.env import EmbeddedServerConfig, EnvConfig
from oasis_torchrl.config.ray import RAY_ALIASES, RayCollectionConfig
from oasis_torchrl.options import REQUIRED, Alias, option
from oasis_torchrl.protocol import FPS

_SIZE = re.compile(r"^(\d+)x(\d+)$")
ROWS = ("frame", "chunk")
DEFAULT_VCODEC = "h264"
"""libx264 through PyAV, decoded by both pyav and torchcodec (``benchmarks/export_speed.py``
compares it with LeRobot's default libsvtav1; BENCHMARKS.md, "LeRobot export")."""
DEFAULT_CRF = 18
"""Quality of the stored video (lower is better and larger; LeRobot's default is 30). A policy
trains on the stored frames and acts on the frames the world streams, so the two must look
alike. At the policy's 96x64, 30 smears the obstacles on the horizon (a few pixels each); 18
keeps them, for more bytes (docs/experiments/2026-11-25-stored-video-quality.md)."""


def parse_size(text: str) -> list[int]:
    """``"HEIGHTxWIDTH"`` -> ``[height, width]``.

    Example:
        >>> parse_size("128x192")
        [128, 192]
    """
    match = _SIZE.match(text.strip().lower())
    if match is None:
        raise ValueError(f"expected HEIGHTxWIDTH such as 128x192, got {text!r}")
    return [int(match[1]), int(match[2])]


@dataclass
class DatasetOutputConfig:
    """Where and how episodes are written (a LeRobot dataset)."""

    root: str = option(REQUIRED, help="dataset folder to write")
    repo_id: str | None = option(None, help="LeRobot repo id (default local/<folder name>)")
    image_size: list[int] | None = option(
        None,
        help="stored frame size HxW, e.g. 128x192 (even; default: full resolution)",
        parse=parse_size,
        metavar="HxW",
    )
    vcodec: str = option(
        DEFAULT_VCODEC,
        help="video codec: h264 (fast), libsvtav1 (LeRobot's default, slow), hevc",
    )
    crf: float = option(
        DEFAULT_CRF, help="video quality, lower is better and larger (LeRobot's default: 30)"
    )
    append: bool = option(False, help="add episodes to an existing dataset")


@dataclass(frozen=True)
class RayRecordingConfig(RayCollectionConfig):
    """Recording on Ray workers, each into its own shard, merged at the end."""

    batch_steps: int = option(8, help="env steps per session between worker reports")
    keep_shards: bool = option(False, help="keep the shards after merging them")


def _record_env() -> EnvConfig:
    return EnvConfig(
        prompts=["urban street"],
        num_envs=2,
        max_steps=128,
        image_size=None,
        server=EmbeddedServerConfig(width=768, height=512),
    )


@dataclass
class RecordConfig(DatasetOutputConfig):
    """``oasis-torchrl record``: drive N envs (autopilot, script or saved policy) and record
    the episodes as a LeRobot dataset."""

    ALIASES: ClassVar[dict[str, Alias]] = {
        "--num-envs": Alias("env.num_envs"),
        "--prompt": Alias("env.prompts", repeat=True),
        "--max-steps": Alias("env.max_steps"),
        "--endpoint": Alias("env.endpoint"),
        "--width": Alias("env.server.width"),
        "--height": Alias("env.server.height"),
        "--fps": Alias("env.server.fps"),
        **RAY_ALIASES,
        "--batch-steps": Alias("ray.batch_steps"),
        "--keep-shards": Alias("ray.keep_shards"),
    }

    episodes: int = option(10, help="episodes to record (with --ray, env.num_envs is unused)", ge=1)
    driver: str = option(
        "auto",
        help="who drives: auto (the autopilot where the endpoint sends ground truth, else the "
        "script) | autopilot | scripted | policy",
    )
    script: str = option("throttle=0.5", help="scripted driver spec (throttle=...,steering=...)")
    policy: str | None = option(
        None,
        help="the policy: saved (a LeRobot policy folder of any type, a PPO checkpoint, a "
        "TorchScript or torch.save file) or served (grpc://host:port)",
    )
    policy_in_keys: str | None = option(
        None,
        help="comma-separated inputs of a plain policy module, nested keys with dots "
        "(e.g. pixels.front,state)",
    )
    seed: int = option(0, help="seed of the episode sequence")
    rows: str = option(
        "frame", help="one dataset row per frame (fps) or per chunk (fps/4)", choices=ROWS
    )
    env: EnvConfig = option(
        default_factory=_record_env,
        help="the env (a remote endpoint reads its key from DECART_API_KEY, never a flag)",
    )
    ray: RayRecordingConfig = option(
        default_factory=RayRecordingConfig, help="record on Ray workers, then merge"
    )

    @property
    def driver_spec(self) -> str:
        """The driver in the one driver grammar (:func:`oasis_torchrl.drivers.load_driver`).

        Example:
            >>> RecordConfig(root="out", driver="scripted", script="throttle=1").driver_spec
            'scripted:throttle=1'
        """
        if self.driver == "scripted":
            return f"scripted:{self.script}"
        if self.driver == "policy":
            return str(self.policy)
        return self.driver

    def __post_init__(self) -> None:
        if self.driver == "policy" and self.policy is None:
            raise ValueError("--driver policy needs --policy FILE")
        if self.ray.enabled and self.append:
            raise ValueError("--append does not work with --ray: record into a new --root")
        if self.ray.server_address and self.env.endpoint != "local":
            raise ValueError("--server-address replaces --endpoint; give one of them")


@dataclass
class ImportConfig(DatasetOutputConfig):
    """``oasis-torchrl import-recordings``: human driving recordings (``episode_*/``
    ``manifest.jsonl`` + PNG frames) into a LeRobot dataset."""

    source: str = option(REQUIRED, help="folder holding episode_*/ recordings", positional=True)
    task: str = option("human driving", help="task of every episode")
    drop_idle: bool = option(False, help="drop each episode's leading all-zero chunks")
    source_size: list[int] = option(
        default_factory=lambda: [512, 768],
        help="HxW of the recorded frames",
        parse=parse_size,
        metavar="HxW",
    )
    fps: int = option(int(FPS), help="world-model frame rate")
