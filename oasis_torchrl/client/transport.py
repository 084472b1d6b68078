"""The session pool's transport: its stubs on one ``grpc.aio`` channel, every unary call with
retries (:class:`~oasis_torchrl.client.retry.RetryPolicy`), a timeout and the API key masked in
errors."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import grpc
from grpc_health.v1 import health_pb2_grpc

from oasis_torchrl.client import health, wire
from oasis_torchrl.client.channel import TlsSetting, create_aio_channel
from oasis_torchrl.client.errors import TransportError
from oasis_torchrl.client.retry import RetryPolicy, acall_with_retry
from oasis_torchrl.proto import a2v_pb2_grpc, sim_pb2_grpc


class Transport:
    """The pool's stubs on one aio channel, with retries, timeout and masked API key.

    Example:
        >>> import asyncio
        >>> async def unreachable():
        ...     channel = await open_channel("http://127.0.0.1:1", None)
        ...     transport = Transport(channel, RetryPolicy.never(), 0.5, "127.0.0.1:1", "k")
        ...     try:
        ...         return await transport.ping()
        ...     finally:
        ...         await channel.close()
        >>> asyncio.run(unreachable())
        False
    """

    def __init__(
        self,
        channel: grpc.aio.Channel,
        policy: RetryPolicy,
        timeout: float | None,
        target: str,
        secret: str | None,
    ) -> None:
        self.a2v = a2v_pb2_grpc.A2VServiceStub(channel)
        self.sim = sim_pb2_grpc.SimServiceStub(channel)
        self.health = health_pb2_grpc.HealthStub(channel)
        self.policy = policy
        self.timeout = timeout
        self.target = target
        self.secret = secret

    async def call(
        self,
        method: Callable[..., Any],
        name: str,
        request: object,
        metadata: wire.Metadata,
        *,
        policy: RetryPolicy | None = None,
        timeout: float | None = None,
    ) -> tuple[Any, grpc.aio.Call]:
        """One unary call with retries; returns the response and its finished call."""

        async def attempt(attempt_timeout: float | None) -> tuple[Any, grpc.aio.Call]:
            call = method(request, timeout=attempt_timeout, metadata=metadata)
            return await call, call

        return await acall_with_retry(
            attempt,
            policy=policy or self.policy,
            method=name,
            timeout=self.timeout if timeout is None else timeout,
            secret=self.secret,
            target=self.target,
        )

    async def ping(self) -> bool:
        """Whether the server's gRPC health service reports SERVING (one try; False if
        unreachable)."""
        try:
            response, _ = await self.call(
                self.health.Check, "Check", health.health_request(), (), policy=RetryPolicy.never()
            )
        except TransportError as error:
            return health.ping_outcome(error)
        return health.is_serving(response)


async def open_channel(endpoint: str, tls: TlsSetting) -> grpc.aio.Channel:
    """A ``grpc.aio`` channel to ``endpoint``, made on the running loop (it binds to it)."""
    return create_aio_channel(endpoint, tls)
