"""Failures of the embedded A2V server, split by how they reach the client."""

from __future__ import annotations

from collections.abc import Mapping

import grpc

from oasis_torchrl.proto import common_pb2


class RequestError(Exception):
    """A rejected request, reported in-band in the response's ``error`` field.

    Example:
        >>> from oasis_torchrl.proto import common_pb2
        >>> error = RequestError(common_pb2.ERROR_CODE_PROMPT_SET, "call Prompt first")
        >>> error.to_proto().code == common_pb2.ERROR_CODE_PROMPT_SET
        True
    """

    def __init__(self, code: int, message: str, details: Mapping[str, str] | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.details = dict(details or {})

    def to_proto(self) -> common_pb2.Error:
        """The ``decart.inference.common.Error`` message for this failure."""
        return common_pb2.Error(code=self.code, message=self.message, details=self.details)


class StatusError(Exception):
    """A failure reported as a gRPC status (transport level), e.g. UNAVAILABLE.

    Example:
        >>> import grpc
        >>> StatusError(grpc.StatusCode.UNAVAILABLE, "try again").status.name
        'UNAVAILABLE'
    """

    def __init__(self, status: grpc.StatusCode, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message
