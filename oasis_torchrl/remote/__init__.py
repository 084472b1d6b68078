"""A policy answered by a policy server: the client side of ``oasis_torchrl.policy.v1``.

- :class:`RemotePolicy` (:mod:`.policy`): a TorchRL policy module and LeRobot-style policy
  answered by a policy server (what :mod:`oasis_torchrl.drivers` builds for
  ``grpc://host:port``); its typed errors are in :mod:`.errors`.
- :mod:`.features`, :mod:`.tensors`: features (name, shape, dtype) and tensors on the wire
  (raw bytes, a dtype and a shape: nothing is pickled), shared with the server.

The server is :mod:`oasis_torchrl.serving`.
"""

from oasis_torchrl.remote.errors import (
    AuthError,
    InvalidInputError,
    PolicyError,
    RateLimitError,
    RemotePolicyError,
    RequestTooLargeError,
    UnavailableError,
)
from oasis_torchrl.remote.features import Feature
from oasis_torchrl.remote.policy import (
    PolicyDescription,
    PolicyStatus,
    RemotePolicy,
    is_policy_url,
)

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
    "is_policy_url",
]
