"""A trained policy served over the network, and the client that drives with it.

The client side (what :mod:`oasis_torchrl.drivers` uses to name ``grpc://host:port``):

- :class:`RemotePolicy` (:mod:`.client`): a TorchRL policy module and LeRobot-style policy
  answered by a policy server; its typed errors are in :mod:`.errors`.
- :mod:`.features`, :mod:`.tensors`: features (name, shape, dtype) and tensors on the wire
  (raw bytes, a dtype and a shape: nothing is pickled).

The server side, ``oasis-torchrl serve-policy``: :mod:`.server` (the gRPC service and
:class:`~oasis_torchrl.serving.server.PolicyServer`), :mod:`.served` (the loaded policy),
:mod:`.host` (loading and state), :mod:`.batching` (one forward pass for concurrent requests),
:mod:`.sessions` (SelectAction's queues), :mod:`.limits` (per-key limits).
"""

from oasis_torchrl.serving.client import PolicyDescription, PolicyStatus, RemotePolicy
from oasis_torchrl.serving.errors import (
    AuthError,
    InvalidInputError,
    PolicyError,
    RateLimitError,
    RemotePolicyError,
    RequestTooLargeError,
    UnavailableError,
)
from oasis_torchrl.serving.features import Feature

__all__ = [
    "AuthError",
    "Feature",
    "InvalidInputError",
    "PolicyDescription",
    "PolicyError",
    "PolicyStatus",
    "RateLimitError",
    "RemotePolicy",
    "RemotePolicyError",
    "RequestTooLargeError",
    "UnavailableError",
]
