"""The gRPC health service (``grpc.health.v1.Health``): what ``ping()`` asks and concludes.

A server without the health service makes ``ping()`` raise :class:`UnsupportedFeatureError`;
an unreachable one answers False.
"""

from __future__ import annotations

import grpc
from grpc_health.v1 import health_pb2

from oasis_torchrl.client.errors import TransportError, UnsupportedFeatureError

NOT_SERVING_CODES = frozenset({grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED})


def health_request() -> health_pb2.HealthCheckRequest:
    """A health check of the whole server (service name "").

    >>> health_request().service
    ''
    """
    return health_pb2.HealthCheckRequest(service="")


def is_serving(response: health_pb2.HealthCheckResponse) -> bool:
    """Whether a health answer says SERVING.

    >>> is_serving(health_pb2.HealthCheckResponse(status=health_pb2.HealthCheckResponse.SERVING))
    True
    """
    return response.status == health_pb2.HealthCheckResponse.SERVING


def ping_outcome(error: TransportError) -> bool:
    """Turn a failed health check into ping's answer: False if the server is unreachable.

    >>> ping_outcome(TransportError(grpc.StatusCode.UNAVAILABLE, "down", method="Check"))
    False
    """
    if error.code() == grpc.StatusCode.UNIMPLEMENTED:
        raise UnsupportedFeatureError(
            "ping needs the gRPC health service (grpc.health.v1.Health), which this server "
            "does not implement"
        ) from error
    if error.code() in NOT_SERVING_CODES:
        return False
    raise error
