"""Typed errors of a policy client, one per way a call to a policy server can fail.

All are :class:`~oasis_torchrl.client.errors.TransportError` (so also ``grpc.RpcError``, with
``code()`` and ``details()``), raised once the retry policy gave up on a transient fault or at
once on a permanent one:

- :class:`AuthError`: the key is missing or rejected (UNAUTHENTICATED, PERMISSION_DENIED).
- :class:`RateLimitError`: a per-key limit (RESOURCE_EXHAUSTED), still hit after the retries.
- :class:`InvalidInputError`: the observation does not match the policy's inputs
  (INVALID_ARGUMENT); :class:`RequestTooLargeError` when it is larger than the server accepts.
- :class:`UnavailableError`: the server is down, still loading the policy, failed to load it,
  or did not answer in time.
- :class:`PolicyError`: the policy raised on this request (INTERNAL); the server keeps serving.
"""

from __future__ import annotations

import grpc

from oasis_torchrl.client.errors import TransportError

_TOO_LARGE = "larger than max"
"""What gRPC says when it refuses a message over the receiver's size limit."""


class RemotePolicyError(TransportError):
    """A call to a policy server failed (see the subclasses).

    Example:
        >>> error = RemotePolicyError(grpc.StatusCode.INTERNAL, "boom", method="PredictChunk")
        >>> str(error)
        'PredictChunk failed: INTERNAL: boom'
    """


class AuthError(RemotePolicyError):
    """The API key is missing or rejected."""


class RateLimitError(RemotePolicyError):
    """A per-key limit of the server (rate, calls in flight, sessions)."""


class InvalidInputError(RemotePolicyError):
    """The observation does not match the policy's inputs (names, shapes, dtypes, finite)."""


class RequestTooLargeError(InvalidInputError):
    """The request is larger than the server accepts (send fewer rows per call)."""


class UnavailableError(RemotePolicyError):
    """The server cannot answer: down, loading the policy, failed to load it, or too slow."""


class PolicyError(RemotePolicyError):
    """The policy raised on this request."""


_BY_STATUS: dict[grpc.StatusCode, type[RemotePolicyError]] = {
    grpc.StatusCode.UNAUTHENTICATED: AuthError,
    grpc.StatusCode.PERMISSION_DENIED: AuthError,
    grpc.StatusCode.RESOURCE_EXHAUSTED: RateLimitError,
    grpc.StatusCode.INVALID_ARGUMENT: InvalidInputError,
    grpc.StatusCode.UNAVAILABLE: UnavailableError,
    grpc.StatusCode.DEADLINE_EXCEEDED: UnavailableError,
    grpc.StatusCode.FAILED_PRECONDITION: UnavailableError,
    grpc.StatusCode.INTERNAL: PolicyError,
}


def typed_error(error: TransportError) -> RemotePolicyError:
    """The typed error of a failed call.

    Example:
        >>> failed = TransportError(grpc.StatusCode.UNAUTHENTICATED, "API key rejected",
        ...                         method="Describe")
        >>> type(typed_error(failed)).__name__
        'AuthError'
    """
    kind = _BY_STATUS.get(error.status, RemotePolicyError)
    if kind is RateLimitError and _TOO_LARGE in error.text:
        kind = RequestTooLargeError
    return kind(
        error.status,
        error.text,
        method=error.method,
        target=error.target,
        attempts=error.attempts,
        elapsed=error.elapsed,
    )


def is_too_large(error: grpc.RpcError) -> bool:
    """Whether gRPC refused a request for its size (no retry can help).

    Example:
        >>> is_too_large(TransportError(grpc.StatusCode.RESOURCE_EXHAUSTED,
        ...     "Received message larger than max (9000 vs. 4000)", method="PredictChunk"))
        True
    """
    code = error.code() if callable(getattr(error, "code", None)) else None
    details = error.details() if callable(getattr(error, "details", None)) else ""
    return code == grpc.StatusCode.RESOURCE_EXHAUSTED and _TOO_LARGE in (details or "")
