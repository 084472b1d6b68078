"""Settings of ``oasis-torchrl play``: a person drives the world model in a browser page."""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from typing import ClassVar

from oasis_torchrl.config.env import EmbeddedServerConfig, EnvConfig
from oasis_torchrl.config.recording import DatasetOutputConfig
from oasis_torchrl.options import Alias, option

LOOPBACK = "127.0.0.1"


def is_loopback(host: str) -> bool:
    """Whether ``host`` is reachable from this machine only (``localhost`` or a loopback IP).

    Example:
        >>> is_loopback("127.0.0.1"), is_loopback("localhost"), is_loopback("0.0.0.0")
        (True, True, False)
    """
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _play_env() -> EnvConfig:
    return EnvConfig(
        prompts=["urban street"],
        num_envs=1,
        max_steps=1500,
        image_size=None,
        server=EmbeddedServerConfig(width=768, height=512),
    )


@dataclass
class PlayConfig(DatasetOutputConfig):
    """``oasis-torchrl play``: serve a page on one port where a person drives the world model
    live (keyboard or gamepad), records episodes into a LeRobot dataset, takes over from a
    policy and replays saved episodes."""

    ALIASES: ClassVar[dict[str, Alias]] = {
        "--prompt": Alias("env.prompts", repeat=True),
        "--max-steps": Alias("env.max_steps"),
        "--endpoint": Alias("env.endpoint"),
        "--width": Alias("env.server.width"),
        "--height": Alias("env.server.height"),
    }

    root: str | None = option(
        None, help="dataset folder the page records into (null: recording is off)"
    )
    host: str = option(
        LOOPBACK,
        help="address the page is served on; any but loopback needs the token of "
        "OASIS_PLAY_TOKEN (a random one is made and logged if it is unset)",
    )
    port: int = option(8080, help="port of the page (0: a free one)", ge=0, le=65535)
    policy: str | None = option(
        None,
        help="a policy that drives until the person takes over: saved (a LeRobot policy "
        "folder, a PPO checkpoint, a TorchScript or torch.save file) or served (grpc://host:port)",
    )
    seed: int = option(0, help="seed of the episode sequence (the embedded server's scenes)")
    jpeg_quality: int = option(
        80, help="JPEG quality 1-100 of the frames sent to the page", ge=1, le=100
    )
    env: EnvConfig = option(
        default_factory=_play_env,
        help="the world (a remote endpoint reads its key from DECART_API_KEY, never a flag)",
    )

    def __post_init__(self) -> None:
        if self.env.num_envs != 1:
            raise ValueError(
                f"the page drives one session: env.num_envs must be 1, got {self.env.num_envs}"
            )
