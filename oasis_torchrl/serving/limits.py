"""Per-key limits of the policy server: a request rate (token bucket) and calls in flight.

A call over a limit fails at once with RESOURCE_EXHAUSTED, before it costs the server
anything; clients retry it with backoff (the project's retry policy does).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import grpc

from oasis_torchrl.sim.auth import key_fingerprint
from oasis_torchrl.sim.errors import StatusError


@dataclass
class _Usage:
    tokens: float
    refilled: float = field(default_factory=time.monotonic)
    in_flight: int = 0


class KeyLimits:
    """Rate and concurrency limits per API key (digest).

    Args:
        rate: requests per second a key may make on average (0: unlimited).
        burst: requests a key may make at once above that rate.
        max_in_flight: calls of a key running at once at most (0: unlimited).

    Example:
        >>> limits = KeyLimits(rate=1.0, burst=2, max_in_flight=0)
        >>> with limits.admit(b"key"), limits.admit(b"key"):
        ...     pass
        >>> with limits.admit(b"key"):
        ...     pass
        Traceback (most recent call last):
        ...
        oasis_torchrl.sim.errors.StatusError: key 6b6579 is over its rate limit of 1.0 \
requests/s (burst 2); retry later
    """

    def __init__(self, rate: float, burst: int, max_in_flight: int) -> None:
        self.rate = rate
        self.burst = burst
        self.max_in_flight = max_in_flight
        self._usage: dict[bytes, _Usage] = {}
        self._lock = threading.Lock()

    @contextmanager
    def admit(self, key: bytes) -> Iterator[None]:
        """Hold one call of ``key`` for the ``with`` block, or raise RESOURCE_EXHAUSTED."""
        with self._lock:
            usage = self._usage.setdefault(key, _Usage(tokens=float(self.burst)))
            self._take_token(key, usage)
            if self.max_in_flight and usage.in_flight >= self.max_in_flight:
                raise StatusError(
                    grpc.StatusCode.RESOURCE_EXHAUSTED,
                    f"key {key_fingerprint(key)} has {usage.in_flight} calls in flight, its "
                    "limit; retry later",
                )
            usage.in_flight += 1
        try:
            yield
        finally:
            with self._lock:
                usage.in_flight -= 1

    def _take_token(self, key: bytes, usage: _Usage) -> None:
        if not self.rate:
            return
        now = time.monotonic()
        usage.tokens = min(self.burst, usage.tokens + (now - usage.refilled) * self.rate)
        usage.refilled = now
        if usage.tokens < 1.0:
            raise StatusError(
                grpc.StatusCode.RESOURCE_EXHAUSTED,
                f"key {key_fingerprint(key)} is over its rate limit of {self.rate} requests/s "
                f"(burst {self.burst}); retry later",
            )
        usage.tokens -= 1.0
