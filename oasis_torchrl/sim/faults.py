"""Injected transient failures, so clients can test their retry logic against the local server."""

from __future__ import annotations

import random
import threading

import grpc

from oasis_torchrl.sim.errors import StatusError


class FailureInjector:
    """Fails a call with UNAVAILABLE with probability ``rate``, reproducibly for a given ``seed``.

    The draw happens before a call touches any state, so retrying a failed call is always safe.
    Draws follow the order calls arrive in; the same call order gives the same failures.

    Example:
        >>> injector = FailureInjector(rate=1.0, seed=0)
        >>> injector.maybe_fail("Infer")
        Traceback (most recent call last):
        ...
        oasis_torchrl.sim.errors.StatusError: injected transient failure of Infer (failure_rate=1.0)
    """

    def __init__(self, rate: float, seed: int) -> None:
        self.rate = rate
        self._random = random.Random(seed)
        self._lock = threading.Lock()

    def maybe_fail(self, method: str) -> None:
        """Raise an UNAVAILABLE :class:`StatusError` for ``method`` if this call's draw fails."""
        if self.rate <= 0.0:
            return
        with self._lock:
            failed = self._random.random() < self.rate
        if failed:
            raise StatusError(
                grpc.StatusCode.UNAVAILABLE,
                f"injected transient failure of {method} (failure_rate={self.rate})",
            )
