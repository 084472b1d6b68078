"""Configuration of the embedded A2V server (one frozen, picklable dataclass)."""

from __future__ import annotations

import json
import os
import re
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import grpc

from oasis_torchrl.options import check_bounds, is_integer, option
from oasis_torchrl.protocol import FORMAT_NAMES, FPS, SERVER_API_KEYS_ENV_VAR, FrameFormat
from oasis_torchrl.sim.encoding import SUPPORTED_FORMATS, format_name

# Keys travel as gRPC metadata (printable ASCII) and in a comma-separated variable.
_API_KEY_PATTERN = re.compile(r"[\x21-\x2b\x2d-\x7e]{1,256}")


def parse_formats(text: str) -> tuple[int, ...]:
    """``"vp9,jpeg"`` -> frame format values, in the given order (names: ``FORMAT_NAMES``).

    Example:
        >>> parse_formats("vp9, jpeg")  # FrameFormat.VP9, FrameFormat.JPEG
        (3, 1)
    """
    names = [name.strip().lower() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in FORMAT_NAMES]
    if unknown or not names:
        raise ValueError(
            f"formats must be a comma-separated list of {', '.join(FORMAT_NAMES)}, got {text!r}"
        )
    return tuple(int(FORMAT_NAMES[name]) for name in names)


def keys_from_env(
    environ: dict[str, str] | None = None, variable: str = SERVER_API_KEYS_ENV_VAR
) -> tuple[str, ...]:
    """API keys listed (comma-separated) in ``variable`` (default ``OASIS_SERVER_API_KEYS``).

    Example:
        >>> keys_from_env({"OASIS_SERVER_API_KEYS": "alpha, beta,,"})
        ('alpha', 'beta')
    """
    raw = (os.environ if environ is None else environ).get(variable, "")
    return tuple(key.strip() for key in raw.split(",") if key.strip())


@dataclass(frozen=True)
class GrpcServerConfig:
    """Where a gRPC server of this project listens and whom it lets in: interface, port, API
    keys, TLS, message size and handler threads (the A2V server's and the policy server's).

    When ``api_keys`` is empty the keys come from the environment variable
    :attr:`API_KEYS_ENV_VAR`. A server with no key at all refuses to start unless
    ``allow_any_key`` is set (then any non-empty key works).

    Example:
        >>> GrpcServerConfig(api_keys=("k",)).endpoint(50051)
        'http://127.0.0.1:50051'
        >>> GrpcServerConfig(api_keys=("two words",))
        Traceback (most recent call last):
        ...
        ValueError: api_keys[0] must be 1-256 printable ASCII characters without spaces or commas
    """

    API_KEYS_ENV_VAR: ClassVar[str] = SERVER_API_KEYS_ENV_VAR
    URL_SCHEMES: ClassVar[tuple[str, str]] = ("http", "https")
    """The scheme of :meth:`endpoint` without and with TLS."""

    host: str = option("127.0.0.1", help="interface to bind")
    port: int = option(0, help="port to bind; 0 picks a free one", ge=0, le=65535)
    api_keys: tuple[str, ...] = option(
        (), help="accepted API keys (default: from the environment; flags are visible to all)"
    )
    allow_any_key: bool = option(False, help="accept any non-empty key")
    max_message_bytes: int = option(64 * 1024, help="largest request, bytes", ge=1024, le=1 << 30)
    tls_cert: str | None = option(None, help="PEM certificate chain (with tls_key)")
    tls_key: str | None = option(None, help="PEM private key (with tls_cert)")
    workers: int = option(32, help="gRPC handler threads", ge=1, le=1024)

    def __post_init__(self) -> None:
        keys = tuple(self.api_keys) or keys_from_env(variable=self.API_KEYS_ENV_VAR)
        object.__setattr__(self, "api_keys", keys)
        # Built outside the config loader too (from JSON in a worker process, in code).
        check_bounds(type(self), lambda key: getattr(self, key))
        self._validate_network()
        self._validate_keys()

    @property
    def tls_enabled(self) -> bool:
        """Whether the server listens with TLS (both ``tls_cert`` and ``tls_key`` given)."""
        return self.tls_cert is not None

    @property
    def address_to_bind(self) -> str:
        """``host:port`` as handed to gRPC (IPv6 hosts in brackets)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{host}:{self.port}"

    def client_address(self, port: int) -> str:
        """``host:port`` a client on this machine dials; wildcard hosts become loopback.

        Example:
            >>> ServerConfig(host="0.0.0.0", api_keys=("k",)).client_address(50051)
            '127.0.0.1:50051'
        """
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"

    def endpoint(self, port: int) -> str:
        """The endpoint URL clients take: ``http://`` or, with TLS, ``https://``.

        Example:
            >>> ServerConfig(api_keys=("k",)).endpoint(50051)
            'http://127.0.0.1:50051'
        """
        return f"{self.URL_SCHEMES[self.tls_enabled]}://{self.client_address(port)}"

    def bind(self, server: grpc.Server) -> int:
        """Add this config's listening port to ``server`` (with TLS when configured); returns
        the bound port."""
        if not self.tls_enabled:
            return server.add_insecure_port(self.address_to_bind)
        credentials = grpc.ssl_server_credentials(
            [(Path(self.tls_key).read_bytes(), Path(self.tls_cert).read_bytes())]
        )
        return server.add_secure_port(self.address_to_bind, credentials)

    def _validate_network(self) -> None:
        if not self.host:
            raise ValueError("host must be a non-empty host name or address")
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError(
                "tls_cert and tls_key must be given together, got "
                f"tls_cert={self.tls_cert!r}, tls_key={self.tls_key!r}"
            )

    def _validate_keys(self) -> None:
        for index, key in enumerate(self.api_keys):
            if not isinstance(key, str) or not _API_KEY_PATTERN.fullmatch(key):
                raise ValueError(
                    f"api_keys[{index}] must be 1-256 printable ASCII characters without "
                    "spaces or commas"
                )


@dataclass(frozen=True)
class ServerConfig(GrpcServerConfig):
    """Everything the embedded A2V server needs; validated on construction.

    When ``api_keys`` is empty the keys come from ``OASIS_SERVER_API_KEYS``. A server with no
    key at all refuses to start unless ``allow_any_key`` is set (then any non-empty key works).

    Example:
        >>> config = ServerConfig(width=96, height=64, api_keys=("secret",))
        >>> config.address_to_bind, config.tls_enabled
        ('127.0.0.1:0', False)
        >>> ServerConfig(width=95)
        Traceback (most recent call last):
        ...
        ValueError: width must be an even integer in [16, 4096], got 95

    ``hosted=True`` makes it the stand-in of the hosted service (at 768x512 unless a smaller
    size is set, e.g. for CPU-bound tests): VP9 only, whatever ``formats`` says.

        >>> ServerConfig(hosted=True, formats=(100,), api_keys=("k",)).formats  # VP9
        (3,)
    """

    width: int = option(768, help="frame width")
    height: int = option(512, help="frame height")
    fps: float = option(FPS, help="frame rate (the world's time step is 1/fps)", ge=1.0, le=240.0)
    latency_ms: float = option(
        0.0, help="delay added to every Infer, emulating a GPU model", ge=0.0, le=600_000.0
    )
    failure_rate: float = option(
        0.0, help="probability of an injected UNAVAILABLE per call", ge=0.0, le=1.0
    )
    failure_seed: int = option(0, help="seed of the injected failures", ge=0, le=(1 << 64) - 1)
    idle_timeout_s: float = option(300.0, help="idle session expiry, seconds", ge=0.001)
    max_sessions: int = option(64, help="open sessions at most", ge=1, le=1 << 20)
    max_sessions_per_key: int = option(
        32, help="open sessions per API key at most", ge=1, le=1 << 20
    )
    max_prompt_chars: int = option(2000, help="longest prompt", ge=1, le=1 << 20)
    processes: int | None = option(
        None,
        help="worker processes running the sessions (null: one per core; 0: all in the "
        "server's process)",
        ge=0,
        le=1024,
    )
    encode_workers: int = option(
        0, help="threads encoding streams per process (0: automatic)", ge=0, le=1024
    )
    formats: tuple[int, ...] = option(
        tuple(int(value) for value in SUPPORTED_FORMATS),
        help="allowed frame formats in preference order, e.g. raw,vp9,jpeg",
        parse=parse_formats,
        metavar="FORMATS",
    )
    vp9_cpu_used: int = option(8, help="libvpx speed 0-8", ge=0, le=8)
    vp9_bit_rate: int | None = option(
        None, help="VP9 bits/s (null: scales with the frame size)", ge=1000, le=1 << 31
    )
    vp9_threads: int = option(1, help="libvpx threads per stream", ge=1, le=64)
    jpeg_quality: int = option(90, help="JPEG quality 1-100", ge=1, le=100)
    hosted: bool = option(
        False,
        help="hosted-like: send only what the hosted Oasis service sends (VP9 frames; no "
        "ground truth, SimService, expert or depth; seeds and the other local extensions "
        "ignored); formats is then vp9",
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        formats = (int(FrameFormat.VP9),) if self.hosted else tuple(self.formats)
        object.__setattr__(self, "formats", formats)
        self._validate_video()

    @property
    def resolved_processes(self) -> int:
        """Worker processes to run: the configured number, or one per core (0: none, the
        sessions run in the server's own process).

        Example:
            >>> ServerConfig(processes=0, api_keys=("k",)).resolved_processes
            0
        """
        return os.cpu_count() or 1 if self.processes is None else self.processes

    @property
    def resolved_encode_workers(self) -> int:
        """Encoder threads per process: the configured number, or automatically one per stream
        or core in a server without workers, and each worker's share of the cores (so that
        workers busy with many sessions do not fight over the cores).

        Example:
            >>> ServerConfig(processes=os.cpu_count(), api_keys=("k",)).resolved_encode_workers
            1
        """
        cores = os.cpu_count() or 1
        if self.encode_workers:
            return self.encode_workers
        if self.resolved_processes == 0:
            return max(3, cores)
        return max(1, cores // self.resolved_processes)

    def encoder_settings(self) -> dict[str, Any]:
        """Keyword arguments for :func:`oasis_torchrl.sim.encoding.make_encoder`."""
        return {
            "vp9_cpu_used": self.vp9_cpu_used,
            "vp9_bit_rate": self.vp9_bit_rate,
            "vp9_threads": self.vp9_threads,
            "jpeg_quality": self.jpeg_quality,
        }

    def to_json(self) -> str:
        """The config as JSON, API keys included (hand it to a child through a pipe, never a
        command line): :meth:`from_json` rebuilds it.

        Example:
            >>> config = ServerConfig(width=96, height=64, api_keys=("k",))
            >>> ServerConfig.from_json(config.to_json()) == config
            True
        """
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> ServerConfig:
        """The config :meth:`to_json` wrote; unknown fields are an error naming them.

        Example:
            >>> ServerConfig.from_json('{"widht": 96}')
            Traceback (most recent call last):
            ...
            ValueError: unknown ServerConfig fields: widht
        """
        values = json.loads(text)
        if not isinstance(values, dict):
            raise ValueError(f"a ServerConfig is a JSON object, got {type(values).__name__}")
        unknown = sorted(set(values) - {item.name for item in fields(cls)})
        if unknown:
            raise ValueError(f"unknown ServerConfig fields: {', '.join(unknown)}")
        sequences = {key: tuple(value) for key, value in values.items() if isinstance(value, list)}
        return cls(**{**values, **sequences})

    def redacted(self) -> dict[str, Any]:
        """The config as a dict fit for logs: API keys replaced by their count."""
        values = asdict(self)
        values["api_keys"] = f"<{len(self.api_keys)} key(s)>"
        return values

    def _validate_video(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if not is_integer(value) or value % 2 or not 16 <= value <= 4096:
                raise ValueError(f"{name} must be an even integer in [16, 4096], got {value!r}")
        if not self.formats:
            raise ValueError("formats must name at least one frame format")
        for frame_format in self.formats:
            if frame_format not in SUPPORTED_FORMATS:
                supported = ", ".join(format_name(f) for f in SUPPORTED_FORMATS)
                raise ValueError(
                    f"formats contains {format_name(frame_format)}; supported: {supported}"
                )
