"""Settings of ``oasis-torchrl serve``: the embedded A2V server's config plus how the command
runs it."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

from oasis_torchrl.options import Alias, option
from oasis_torchrl.sim.config import ServerConfig


@dataclass(frozen=True)
class ServeConfig(ServerConfig):
    """``oasis-torchrl serve``: the embedded A2V server (procedural driving simulator) until
    SIGTERM/SIGINT. API keys are better passed in ``OASIS_SERVER_API_KEYS`` than as flags:
    command lines are visible to every user of the machine."""

    ALIASES: ClassVar[dict[str, Alias]] = {
        "--api-key": Alias("api_keys", repeat=True),
        "--idle-timeout": Alias("idle_timeout_s"),
    }

    port_file: str | None = option(None, help="write the bound port to this file once serving")
    grace: float = option(2.0, help="seconds in-flight calls get at shutdown")

    def server_config(self) -> ServerConfig:
        """The server's own settings (without the command's).

        Example:
            >>> ServeConfig(width=96, height=64, api_keys=("k",)).server_config().width
            96
        """
        names = [item.name for item in fields(ServerConfig)]
        return ServerConfig(**{name: getattr(self, name) for name in names})
