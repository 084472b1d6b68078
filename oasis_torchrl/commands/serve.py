"""``oasis-torchrl serve``: run the embedded A2V server until SIGTERM or SIGINT.

Every :class:`~oasis_torchrl.sim.config.ServerConfig` field has a flag. API keys are better
passed in ``OASIS_SERVER_API_KEYS`` than with ``--api-key``: command lines are visible to every
user of the machine.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

from oasis_torchrl.protocol import FORMAT_NAMES

if TYPE_CHECKING:
    from oasis_torchrl.sim.config import ServerConfig

logger = logging.getLogger(__name__)

NAME = "serve"
HELP = "run the embedded A2V server (procedural driving simulator) until SIGTERM/SIGINT"


def _parse_formats(text: str) -> tuple[int, ...]:
    """``"vp9,jpeg"`` -> format enum values, in the given order."""
    names = [name.strip().lower() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in FORMAT_NAMES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"formats must be a comma-separated list of {', '.join(FORMAT_NAMES)}, got {text!r}"
        )
    return tuple(FORMAT_NAMES[name] for name in names)


# (flag, ServerConfig field, argparse keywords); every default is None = the config default.
_FLAGS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("--host", "host", {"help": "interface to bind (default 127.0.0.1)"}),
    ("--port", "port", {"type": int, "help": "port to bind; 0 picks a free one (default 0)"}),
    ("--width", "width", {"type": int, "help": "frame width (default 768)"}),
    ("--height", "height", {"type": int, "help": "frame height (default 512)"}),
    ("--fps", "fps", {"type": float, "help": "frame rate (default 20)"}),
    (
        "--api-key",
        "api_keys",
        {
            "action": "append",
            "metavar": "KEY",
            "help": "accepted API key, repeatable (default: $OASIS_SERVER_API_KEYS)",
        },
    ),
    ("--allow-any-key", "allow_any_key", {"action": "store_true", "help": "accept any key"}),
    ("--latency-ms", "latency_ms", {"type": float, "help": "delay added to every Infer"}),
    ("--failure-rate", "failure_rate", {"type": float, "help": "injected UNAVAILABLE rate"}),
    ("--failure-seed", "failure_seed", {"type": int, "help": "seed of the injected failures"}),
    ("--idle-timeout", "idle_timeout_s", {"type": float, "help": "idle session expiry, seconds"}),
    ("--max-sessions", "max_sessions", {"type": int, "help": "open sessions at most"}),
    ("--max-sessions-per-key", "max_sessions_per_key", {"type": int, "help": "per API key"}),
    ("--max-prompt-chars", "max_prompt_chars", {"type": int, "help": "longest prompt"}),
    ("--max-message-bytes", "max_message_bytes", {"type": int, "help": "largest request"}),
    ("--tls-cert", "tls_cert", {"help": "PEM certificate chain (with --tls-key)"}),
    ("--tls-key", "tls_key", {"help": "PEM private key (with --tls-cert)"}),
    ("--workers", "workers", {"type": int, "help": "gRPC handler threads (default 32)"}),
    (
        "--processes",
        "processes",
        {
            "type": int,
            "help": "worker processes running the sessions (default: one per core; "
            "0: all in the server's process)",
        },
    ),
    ("--encode-workers", "encode_workers", {"type": int, "help": "encoder threads (0: auto)"}),
    (
        "--formats",
        "formats",
        {"type": _parse_formats, "help": "allowed formats, e.g. vp9,jpeg (default raw,vp9,jpeg)"},
    ),
    ("--vp9-cpu-used", "vp9_cpu_used", {"type": int, "help": "libvpx speed 0-8 (default 8)"}),
    ("--vp9-bit-rate", "vp9_bit_rate", {"type": int, "help": "VP9 bits/s (default: by size)"}),
    ("--vp9-threads", "vp9_threads", {"type": int, "help": "libvpx threads per stream"}),
    ("--jpeg-quality", "jpeg_quality", {"type": int, "help": "JPEG quality 1-100 (default 90)"}),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add one flag per config field, plus ``--port-file`` and ``--grace``."""
    for flag, field, options in _FLAGS:
        if options.get("action") != "store_true":
            options = {"metavar": flag[2:].upper().replace("-", "_"), **options}
        parser.add_argument(flag, dest=field, default=None, **options)
    parser.add_argument(
        "--port-file", type=Path, help="write the bound port to this file once serving"
    )
    parser.add_argument(
        "--grace", type=float, default=2.0, help="seconds in-flight calls get at shutdown"
    )


def config_from_args(args: argparse.Namespace) -> ServerConfig:
    """The :class:`ServerConfig` the parsed flags describe (unset flags keep defaults).

    Example:
        >>> import argparse
        >>> parser = argparse.ArgumentParser()
        >>> add_arguments(parser)
        >>> config_from_args(parser.parse_args(["--width", "96", "--height", "64",
        ...                                     "--api-key", "k"])).width
        96
    """
    from oasis_torchrl.sim.config import ServerConfig

    values = {field: getattr(args, field) for _, field, _ in _FLAGS}
    return ServerConfig(**{field: value for field, value in values.items() if value is not None})


def run(args: argparse.Namespace) -> int:
    """Start the server, write ``--port-file``, serve until a signal, then stop cleanly."""
    from oasis_torchrl.sim.serving import serve

    try:
        config = config_from_args(args)
    except ValueError as error:
        logger.error("cannot start the server: %s", error)
        return 2
    return serve(config, port_file=args.port_file, grace=args.grace)
