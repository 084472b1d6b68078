"""Settings of the policy server (:class:`PolicyServerConfig`) and of ``oasis-torchrl
serve-policy`` (:class:`ServePolicyConfig`): where it listens, whom it lets in, its limits and
how it batches requests."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from oasis_torchrl.options import REQUIRED, Alias, option
from oasis_torchrl.protocol import POLICY_SERVER_API_KEYS_ENV_VAR
from oasis_torchrl.sim.config import GrpcServerConfig

if TYPE_CHECKING:
    from oasis_torchrl.remote.features import Feature


@dataclass(frozen=True)
class PolicyServerConfig(GrpcServerConfig):
    """The policy server: listening, API keys (default ``OASIS_POLICY_SERVER_API_KEYS``),
    per-key limits, request sizes, sessions and batching.

    Example:
        >>> config = PolicyServerConfig(api_keys=("k",))
        >>> config.endpoint(50052), config.max_message_bytes
        ('grpc://127.0.0.1:50052', 8388608)
        >>> PolicyServerConfig(api_keys=("k",), batch_rows=0)
        Traceback (most recent call last):
        ...
        ValueError: batch_rows must be an integer in [1, 65536], got 0
    """

    API_KEYS_ENV_VAR: ClassVar[str] = POLICY_SERVER_API_KEYS_ENV_VAR
    URL_SCHEMES: ClassVar[tuple[str, str]] = ("grpc", "grpcs")

    max_message_bytes: int = option(8 << 20, help="largest request, bytes", ge=1024, le=1 << 30)
    max_rows: int = option(
        64, help="rows (observations) one request may hold at most", ge=1, le=1 << 16
    )
    batch_rows: int = option(
        256,
        help="rows one forward pass merges from concurrent requests at most (1: no merging)",
        ge=1,
        le=1 << 16,
    )
    batch_wait_ms: float = option(
        2.0,
        help="how long the first request of a batch waits for others at most, ms",
        ge=0.0,
        le=10_000.0,
    )
    max_sessions: int = option(1024, help="SelectAction sessions held at most", ge=1, le=1 << 20)
    max_sessions_per_key: int = option(
        256, help="SelectAction sessions of one API key at most", ge=1, le=1 << 20
    )
    session_idle_s: float = option(
        600.0, help="an unused session is forgotten after this, s", ge=0.001
    )
    rate_per_key: float = option(0.0, help="requests per second per API key (0: unlimited)", ge=0.0)
    burst_per_key: int = option(
        64, help="requests a key may make at once above its rate", ge=1, le=1 << 20
    )
    max_in_flight_per_key: int = option(
        64, help="calls of one API key running at once (0: any)", ge=0, le=1 << 20
    )


@dataclass(frozen=True)
class ServePolicyConfig(PolicyServerConfig):
    """``oasis-torchrl serve-policy``: serve a trained policy over gRPC until SIGTERM/SIGINT.
    API keys are better passed in ``OASIS_POLICY_SERVER_API_KEYS`` than as flags: command
    lines are visible to every user of the machine."""

    ALIASES: ClassVar[dict[str, Alias]] = {
        "--api-key": Alias("api_keys", repeat=True),
        "--input": Alias("inputs", repeat=True),
    }

    policy: str = option(
        REQUIRED,
        help="the policy: a shipped policy (pretrained:<name>), a LeRobot policy folder, a PPO "
        "checkpoint, a TorchScript or torch.save file",
        positional=True,
    )
    inputs: tuple[str, ...] = option(
        (),
        help="what a plain saved module reads, in order, as NAME:DTYPE:SHAPE "
        "(e.g. pixels.front:uint8:4x64x96x3); policies that declare their inputs need none",
    )
    threads: int = option(
        0,
        help="threads of the policy's forward passes (torch intra-op; 0: torch's default)",
        ge=0,
        le=1024,
    )
    port_file: str | None = option(None, help="write the bound port to this file once serving")
    grace: float = option(2.0, help="seconds in-flight calls get at shutdown")

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "inputs", tuple(self.inputs))
        self.input_features()

    def input_features(self) -> list[Feature] | None:
        """The declared inputs as features (None: the policy declares its own).

        Example:
            >>> ServePolicyConfig(policy="p.pt", inputs=("state:float32:2",), api_keys=("k",)
            ...                   ).input_features()[0].shape
            (2,)
        """
        from oasis_torchrl.remote.features import Feature

        return [Feature.parse(text) for text in self.inputs] or None
