"""The served policy's life in a server: loading in the background (the server answers Status
meanwhile), then ready, its forward passes batched, or failed, with the reason."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import grpc
import torch
from tensordict import TensorDictBase

from oasis_torchrl.proto import policy_pb2
from oasis_torchrl.serving.batching import Batcher
from oasis_torchrl.serving.served import ServedPolicy
from oasis_torchrl.sim.errors import StatusError

logger = logging.getLogger(__name__)

Loader = Callable[[], ServedPolicy]


class PolicyHost:
    """Loads a policy in a thread, then runs its forward passes through a :class:`Batcher`.

    Args:
        load: builds the policy (e.g. ``lambda: load_served_policy(path)``).
        name: what the policy is called until it has loaded.
        max_rows: the batcher's largest batch, in rows.
        max_wait: seconds the first request of a batch waits for others at most.
        on_ready: called once the policy has loaded.

    Example:
        >>> from oasis_torchrl.drivers import PolicyDriver
        >>> from oasis_torchrl.models import DrivingNet
        >>> host = PolicyHost(lambda: ServedPolicy.of_driver(
        ...     PolicyDriver.of_network(DrivingNet()), "fresh"), "fresh", max_rows=8, max_wait=0)
        >>> host.start().wait(60), host.state == policy_pb2.STATE_READY
        (True, True)
        >>> host.close()
    """

    def __init__(
        self,
        load: Loader,
        name: str,
        *,
        max_rows: int,
        max_wait: float,
        on_ready: Callable[[], None] | None = None,
    ) -> None:
        self.name = name
        self.state = policy_pb2.STATE_LOADING
        self.reason = ""
        self._load = load
        self._batching = {"max_rows": max_rows, "max_wait": max_wait}
        self._on_ready = on_ready
        self._policy: ServedPolicy | None = None
        self._batcher: Batcher | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._load_policy, name="policy-loader", daemon=True)

    def start(self) -> PolicyHost:
        """Start loading; returns ``self``."""
        self._thread.start()
        return self

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the policy has loaded or failed (or ``timeout``); True when it is over."""
        return self._done.wait(timeout)

    @property
    def policy(self) -> ServedPolicy:
        """The loaded policy; UNAVAILABLE while loading, FAILED_PRECONDITION if it failed."""
        return self._ready()[0]

    def predict_chunk(self, observation: TensorDictBase) -> torch.Tensor:
        """The chunks of ``observation``'s rows, from a forward pass shared with concurrent
        requests; raises :class:`~oasis_torchrl.serving.batching.PolicyRaised`."""
        return self._ready()[1](observation)

    def _ready(self) -> tuple[ServedPolicy, Batcher]:
        if self._policy is not None and self._batcher is not None:
            return self._policy, self._batcher
        if self.state == policy_pb2.STATE_FAILED:
            raise StatusError(
                grpc.StatusCode.FAILED_PRECONDITION,
                f"the policy {self.name} failed to load: {self.reason}",
            )
        raise StatusError(grpc.StatusCode.UNAVAILABLE, f"the policy {self.name} is still loading")

    @property
    def stats(self) -> dict[str, int]:
        """Requests answered and forward passes made so far."""
        stats = self._batcher.stats if self._batcher is not None else None
        return {} if stats is None else vars(stats).copy()

    def close(self) -> None:
        """Stop the batcher (queued requests are answered first)."""
        self._thread.join()
        if self._batcher is not None:
            self._batcher.close()

    def _load_policy(self) -> None:
        try:
            policy = self._load()
            self._batcher = Batcher(policy.predict_chunk, **self._batching)
            self.name = policy.name
            self._policy = policy
            self.state = policy_pb2.STATE_READY
        except Exception as error:
            logger.exception("cannot load the policy %s", self.name)
            self.reason = f"{type(error).__name__}: {error}"
            self.state = policy_pb2.STATE_FAILED
        finally:
            self._done.set()
        if self._on_ready is not None and self._policy is not None:
            self._on_ready()
