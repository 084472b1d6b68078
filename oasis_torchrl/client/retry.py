"""Retry policy for transient gRPC failures: capped exponential backoff with full jitter.

What is retried, and why it is safe:

- ``UNAVAILABLE`` and ``RESOURCE_EXHAUSTED`` on every method: the server did not take the call
  (connection refused or reset, overload), or, if it did, repeating it is harmless (see below).
- ``DEADLINE_EXCEEDED`` on ``Infer`` only. The server may have run the Infer and only the
  answer was lost. Re-sending the *same* sequence number makes the A2V server replay its cached
  response for that number byte for byte, so the world does not advance twice and the client's
  stateful VP9 decoders see every packet exactly once. Other methods are not retried on a
  deadline: a repeated Initialize would leak a session, and Prompt/Finish callers need to know.

Everything else (in-band A2V errors, ``INVALID_ARGUMENT``, ``UNAUTHENTICATED``, ...) is raised at
once. Attempts stop at ``max_attempts`` or when the next wait would cross ``deadline`` (seconds
for the whole logical call, all attempts and waits included); each attempt's own timeout is cut
to what remains of the deadline.
"""

from __future__ import annotations

import asyncio
import logging
import random
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import grpc

from oasis_torchrl.client.errors import TransportError, transport_error_from_rpc

logger = logging.getLogger(__name__)

TRANSIENT_CODES = frozenset({grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.RESOURCE_EXHAUSTED})
IDEMPOTENT_METHODS = frozenset({"Infer"})


@dataclass(frozen=True)
class RetryPolicy:
    """How often and how long to retry a transient gRPC failure.

    >>> policy = RetryPolicy(max_attempts=3, base_delay=0.1, jitter=False)
    >>> [policy.backoff(attempt) for attempt in (1, 2, 3)]
    [0.1, 0.2, 0.4]
    >>> policy.is_retryable(grpc.StatusCode.DEADLINE_EXCEEDED, "Infer")
    True
    """

    max_attempts: int = 5
    base_delay: float = 0.05
    max_delay: float = 2.0
    deadline: float | None = None
    jitter: bool = True

    def __post_init__(self) -> None:
        if self.max_attempts < 1:
            raise ValueError(f"max_attempts must be >= 1, got {self.max_attempts}")
        if self.base_delay < 0 or self.max_delay < self.base_delay:
            raise ValueError(
                "need 0 <= base_delay <= max_delay, got "
                f"base_delay={self.base_delay}, max_delay={self.max_delay}"
            )
        if self.deadline is not None and self.deadline <= 0:
            raise ValueError(f"deadline must be positive seconds or None, got {self.deadline}")

    @classmethod
    def never(cls) -> RetryPolicy:
        """A policy that makes a single attempt (the official SDK's behaviour).

        >>> RetryPolicy.never().max_attempts
        1
        """
        return cls(max_attempts=1)

    def is_retryable(self, code: grpc.StatusCode | None, method: str) -> bool:
        """Whether a failure with ``code`` on ``method`` may be retried."""
        if code in TRANSIENT_CODES:
            return True
        return code == grpc.StatusCode.DEADLINE_EXCEEDED and method in IDEMPOTENT_METHODS

    def backoff(self, attempt: int, rng: random.Random | None = None) -> float:
        """Wait before retry number ``attempt`` (1-based): capped exponential, full jitter."""
        ceiling = min(self.max_delay, self.base_delay * 2 ** (attempt - 1))
        return (rng or random).uniform(0.0, ceiling) if self.jitter else ceiling


class RetryBudget:
    """Attempts and deadline of one logical call; decides whether and when to retry.

    >>> budget = RetryBudget(RetryPolicy(max_attempts=2, jitter=False), "Infer", timeout=5.0)
    >>> budget.attempt_timeout()
    5.0
    >>> budget.next_delay(grpc.StatusCode.UNAVAILABLE)
    0.05
    >>> budget.next_delay(grpc.StatusCode.UNAVAILABLE) is None
    True
    """

    def __init__(self, policy: RetryPolicy, method: str, timeout: float | None) -> None:
        self.policy = policy
        self.method = method
        self.timeout = timeout
        self.attempts = 1
        self._start = time.monotonic()

    @property
    def elapsed(self) -> float:
        """Seconds since the first attempt started."""
        return time.monotonic() - self._start

    def attempt_timeout(self) -> float | None:
        """The timeout for the next attempt: the call timeout cut to the remaining deadline."""
        if self.policy.deadline is None:
            return self.timeout
        remaining = max(self.policy.deadline - self.elapsed, 0.001)
        return remaining if self.timeout is None else min(self.timeout, remaining)

    def next_delay(self, code: grpc.StatusCode | None) -> float | None:
        """Seconds to wait before the next attempt, or None to give up."""
        if not self.policy.is_retryable(code, self.method):
            return None
        if self.attempts >= self.policy.max_attempts:
            return None
        delay = self.policy.backoff(self.attempts)
        deadline = self.policy.deadline
        if deadline is not None and self.elapsed + delay >= deadline:
            return None
        logger.debug(
            "%s failed with %s (attempt %d of %d); retrying in %.3f s",
            self.method,
            code.name if code is not None else "an unknown status",
            self.attempts,
            self.policy.max_attempts,
            delay,
        )
        self.attempts += 1
        return delay

    def give_up(
        self, error: grpc.RpcError, secret: str | None, target: str | None
    ) -> TransportError:
        """The error to raise once retrying is over (API key masked)."""
        return transport_error_from_rpc(
            error,
            method=self.method,
            secret=secret,
            target=target,
            attempts=self.attempts,
            elapsed=self.elapsed,
        )


def call_with_retry[T](
    call: Callable[[float | None], T],
    *,
    policy: RetryPolicy,
    method: str,
    timeout: float | None,
    secret: str | None = None,
    target: str | None = None,
) -> T:
    """Run ``call(attempt_timeout)`` until it succeeds or the policy gives up (blocking).

    >>> call_with_retry(lambda timeout: "ok", policy=RetryPolicy(), method="Infer", timeout=1.0)
    'ok'
    """
    budget = RetryBudget(policy, method, timeout)
    while True:
        try:
            return call(budget.attempt_timeout())
        except grpc.RpcError as error:
            delay = budget.next_delay(_status(error))
            if delay is None:
                raise budget.give_up(error, secret, target) from None
        time.sleep(delay)


async def acall_with_retry[T](
    call: Callable[[float | None], Awaitable[T]],
    *,
    policy: RetryPolicy,
    method: str,
    timeout: float | None,
    secret: str | None = None,
    target: str | None = None,
) -> T:
    """Await ``call(attempt_timeout)`` until it succeeds or the policy gives up (asyncio).

    >>> async def ok(timeout): return "ok"
    >>> asyncio.run(acall_with_retry(ok, policy=RetryPolicy(), method="Infer", timeout=1.0))
    'ok'
    """
    budget = RetryBudget(policy, method, timeout)
    while True:
        try:
            return await call(budget.attempt_timeout())
        except grpc.RpcError as error:
            delay = budget.next_delay(_status(error))
            if delay is None:
                raise budget.give_up(error, secret, target) from None
        await asyncio.sleep(delay)


def _status(error: grpc.RpcError) -> grpc.StatusCode | None:
    code = getattr(error, "code", None)
    return code() if callable(code) else None
