"""Endpoint parsing, TLS and gRPC channel construction (sync and asyncio).

The URL rules are the official SDK's: ``https://host[:port]`` means TLS, ``http://host[:port]``
plaintext, a bare ``host:port`` TLS unless ``tls=False``; an explicit ``tls`` bool overrides the
scheme. As an extension ``tls`` may also be a ``grpc.ChannelCredentials`` (e.g. a private CA).
"""

from __future__ import annotations

import functools
import ipaddress
import socket
from dataclasses import dataclass
from urllib.parse import urlparse, urlsplit

import grpc

TlsSetting = bool | grpc.ChannelCredentials | None

CHANNEL_OPTIONS: tuple[tuple[str, int], ...] = (
    # Frames of 12 images can exceed gRPC's 4 MB default at large sizes or with JPEG.
    ("grpc.max_receive_message_length", -1),
    # Reconnect quickly after a server restart: the default backoff grows to 120 s, far longer
    # than any retry policy waits, which would turn a short outage into lost sessions.
    ("grpc.initial_reconnect_backoff_ms", 100),
    ("grpc.min_reconnect_backoff_ms", 100),
    ("grpc.max_reconnect_backoff_ms", 1000),
)


@dataclass(frozen=True)
class ChannelTarget:
    """Where and how to connect: gRPC target string and TLS credentials (None for plaintext).

    >>> parse_endpoint("http://127.0.0.1:50051").address
    '127.0.0.1:50051'
    """

    address: str
    credentials: grpc.ChannelCredentials | None

    @property
    def secure(self) -> bool:
        """Whether the channel uses TLS."""
        return self.credentials is not None


def parse_endpoint(endpoint: str, tls: TlsSetting = None) -> ChannelTarget:
    """Turn an endpoint URL (or bare ``host:port``) into a :class:`ChannelTarget`.

    >>> parse_endpoint("https://oasis-grpc.decart.ai").secure
    True
    >>> parse_endpoint("localhost:50051", tls=False).secure
    False
    """
    parsed = urlparse(endpoint)
    if parsed.scheme in ("http", "https"):
        path = "" if parsed.path == "/" else parsed.path.rstrip("/")
        address = parsed.netloc + path
        scheme_secure = parsed.scheme == "https"
    else:
        address = endpoint
        scheme_secure = True
    if not address:
        raise ValueError(f"Invalid endpoint: {endpoint!r}")
    return ChannelTarget(address, _credentials(scheme_secure, tls))


def is_on_this_machine(endpoint: str) -> bool:
    """Whether ``endpoint``'s host is this machine: a loopback address, ``localhost``, this
    machine's name, or one of its addresses (names are never looked up).

    >>> is_on_this_machine("http://127.0.0.1:50051"), is_on_this_machine("[::1]:5")
    (True, True)
    >>> is_on_this_machine("https://oasis-grpc.decart.ai")
    False
    """
    host = urlsplit("//" + parse_endpoint(endpoint, tls=False).address).hostname or ""
    if host == "localhost" or host in (socket.gethostname(), socket.getfqdn()):
        return True
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        return False
    return ip.is_loopback or ip.is_unspecified or host in _this_machines_addresses()


@functools.cache
def _this_machines_addresses() -> frozenset[str]:
    try:
        return frozenset(socket.gethostbyname_ex(socket.gethostname())[2])
    except OSError:
        return frozenset()


def create_channel(endpoint: str, tls: TlsSetting = None) -> grpc.Channel:
    """Open a blocking gRPC channel to ``endpoint``.

    >>> channel = create_channel("http://127.0.0.1:1")
    >>> channel.close()
    """
    target = parse_endpoint(endpoint, tls)
    if target.credentials is None:
        return grpc.insecure_channel(target.address, options=CHANNEL_OPTIONS)
    return grpc.secure_channel(target.address, target.credentials, options=CHANNEL_OPTIONS)


def create_aio_channel(endpoint: str, tls: TlsSetting = None) -> grpc.aio.Channel:
    """Open an asyncio gRPC channel to ``endpoint`` (call from inside the event loop).

    >>> import asyncio
    >>> async def open_and_close():
    ...     await create_aio_channel("http://127.0.0.1:1").close()
    >>> asyncio.run(open_and_close())
    """
    target = parse_endpoint(endpoint, tls)
    if target.credentials is None:
        return grpc.aio.insecure_channel(target.address, options=CHANNEL_OPTIONS)
    return grpc.aio.secure_channel(target.address, target.credentials, options=CHANNEL_OPTIONS)


def _credentials(scheme_secure: bool, tls: TlsSetting) -> grpc.ChannelCredentials | None:
    if isinstance(tls, grpc.ChannelCredentials):
        return tls
    if tls is not None and not isinstance(tls, bool):
        raise TypeError(f"tls must be None, a bool or grpc.ChannelCredentials, got {type(tls)!r}")
    secure = scheme_secure if tls is None else tls
    return grpc.ssl_channel_credentials() if secure else None
