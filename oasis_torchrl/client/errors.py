"""Exceptions raised by the A2V client layer.

The hierarchy extends the official SDK's (``DecartRoboticsError`` > ``A2VError``) so code written
against ``decart_oasis`` keeps catching what it caught before, while callers that want to react
differently can tell the failure kinds apart:

- :class:`A2VError` and its subclasses: the server answered with an in-band ``Error``.
  :class:`SessionLostError` (session unknown or finished: re-Initialize), :class:`SequenceError`
  (sequence number mismatch: re-Prompt), :class:`PermanentA2VError` (anything else: a caller or
  configuration problem that no retry can fix).
- :class:`TransportError`: a gRPC status after the retry policy gave up. It is also a
  ``grpc.RpcError`` (with ``code()`` and ``details()``), like what the official SDK lets through.
- :class:`DecodeError`: a frame could not be decoded (the stream is out of sync).
- :class:`UnsupportedFeatureError`: the server lacks an optional service (health, SimService).

Every error may carry ``row``, the pool row it happened on, shown at the start of its message.
Text coming from the server is scrubbed of the API key before it reaches a message.
"""

from __future__ import annotations

import enum

import grpc

from oasis_torchrl.proto import common_pb2

MASK = "***"


class ErrorCode(enum.IntEnum):
    """``decart.inference.common.ErrorCode`` as a Python enum.

    >>> ErrorCode(9).name
    'INVALID_API_KEY'
    """

    UNSPECIFIED = 0
    INVALID_SESSION = 1
    ALREADY_FINISHED = 2
    INVALID_REQUEST = 3
    INVALID_MODEL = 4
    INVALID_FORMAT = 5
    INVALID_ENVIRONMENTS = 6
    PROMPT_SET = 7
    UNSUPPORTED_SDK_VERSION = 8
    INVALID_API_KEY = 9


def mask_secret(text: str, secret: str | None) -> str:
    """Replace every occurrence of ``secret`` in ``text`` by ``***``.

    >>> mask_secret("bad key sk-123", "sk-123")
    'bad key ***'
    """
    return text.replace(secret, MASK) if secret else text


class DecartRoboticsError(RuntimeError):
    """Base class of every error this client raises (same name and base as the official SDK).

    >>> str(DecartRoboticsError("A2V session is not initialized"))
    'A2V session is not initialized'
    """

    row: int | None = None

    def __str__(self) -> str:
        text = self._describe()
        return text if self.row is None else f"session row {self.row}: {text}"

    def _describe(self) -> str:
        return super().__str__()


class A2VError(DecartRoboticsError):
    """In-band error returned by the A2V service: ``code``, ``message`` and ``details``.

    >>> error = A2VError(9, "unknown API key")
    >>> (error.code == 9, error.code.name, str(error))
    (True, 'INVALID_API_KEY', 'A2V error 9 (INVALID_API_KEY): unknown API key')
    """

    def __init__(
        self,
        code: int,
        message: str,
        details: dict[str, str] | None = None,
        *,
        row: int | None = None,
    ) -> None:
        super().__init__(code, message, details)
        self.code: int = _as_error_code(code)
        self.message = message
        self.details: dict[str, str] = dict(details or {})
        self.row = row

    def _describe(self) -> str:
        name = self.code.name if isinstance(self.code, ErrorCode) else "UNKNOWN"
        text = f"A2V error {int(self.code)} ({name}): {self.message}"
        return f"{text} ({self.details})" if self.details else text


class SessionLostError(A2VError):
    """The server no longer knows the session (INVALID_SESSION or ALREADY_FINISHED).

    >>> isinstance(a2v_error_from_proto(common_pb2.Error(code=1, message="gone")), SessionLostError)
    True
    """


class SequenceError(A2VError):
    """The server expected another sequence number: client and server rollouts diverged.

    >>> error = common_pb2.Error(code=3, message="expected sequence_num 2, got 5")
    >>> isinstance(a2v_error_from_proto(error), SequenceError)
    True
    """


class PermanentA2VError(A2VError):
    """An A2V error no retry can fix (bad key, bad request, unsupported SDK or format, ...).

    >>> isinstance(a2v_error_from_proto(common_pb2.Error(code=9, message="no")), PermanentA2VError)
    True
    """


class TransportError(DecartRoboticsError, grpc.RpcError):
    """A gRPC call failed with a non-OK status (after the retry policy gave up).

    >>> error = TransportError(grpc.StatusCode.UNAVAILABLE, "connection refused", method="Infer")
    >>> (error.code(), str(error))
    (<StatusCode.UNAVAILABLE: (14, 'unavailable')>, 'Infer failed: UNAVAILABLE: connection refused')
    """

    def __init__(
        self,
        status: grpc.StatusCode,
        text: str,
        *,
        method: str,
        target: str | None = None,
        attempts: int = 1,
        elapsed: float | None = None,
    ) -> None:
        super().__init__(status, text, method)
        self.status = status
        self.text = text
        self.method = method
        self.target = target
        self.attempts = attempts
        self.elapsed = elapsed

    def code(self) -> grpc.StatusCode:
        """The gRPC status code, as on ``grpc.RpcError``/``grpc.Call``."""
        return self.status

    def details(self) -> str:
        """The gRPC status details text (API key masked), as on ``grpc.Call``."""
        return self.text

    def _describe(self) -> str:
        where = f" to {self.target}" if self.target else ""
        tries = ""
        if self.attempts > 1:
            tries = f" after {self.attempts} attempts"
            if self.elapsed is not None:
                tries += f" in {self.elapsed:.2f} s"
        return f"{self.method}{where} failed{tries}: {self.status.name}: {self.text}"


class DecodeError(DecartRoboticsError):
    """A frame of ``stream`` could not be decoded: the decoder is out of sync with the server.

    >>> str(DecodeError("front", "VP9 packet produced no frame"))
    "cannot decode stream 'front': VP9 packet produced no frame"
    """

    def __init__(self, stream: str, reason: str) -> None:
        super().__init__(stream, reason)
        self.stream = stream
        self.reason = reason

    def _describe(self) -> str:
        return f"cannot decode stream {self.stream!r}: {self.reason}"


class UnsupportedFeatureError(DecartRoboticsError):
    """The server does not implement an optional service this call needs.

    >>> str(UnsupportedFeatureError("depth needs oasis_torchrl.sim.v1.SimService"))
    'depth needs oasis_torchrl.sim.v1.SimService'
    """


def is_sequence_error(code: int, message: str, details: dict[str, str]) -> bool:
    """Whether an INVALID_REQUEST error is about the sequence number (rollouts diverged).

    >>> is_sequence_error(3, "unexpected sequence_num: expected 1, got 3", {})
    True
    >>> is_sequence_error(3, "actions must hold 4 entries", {})
    False
    """
    if code != ErrorCode.INVALID_REQUEST:
        return False
    text = " ".join([message, *details.keys(), *details.values()]).lower()
    return "sequence" in text


def a2v_error_from_proto(error: common_pb2.Error, secret: str | None = None) -> A2VError:
    """Build the matching :class:`A2VError` subclass from a proto ``Error``, masking ``secret``.

    >>> a2v_error_from_proto(common_pb2.Error(code=9, message="key k1 unknown"), "k1").message
    'key *** unknown'
    """
    message = mask_secret(error.message, secret)
    details = {mask_secret(k, secret): mask_secret(v, secret) for k, v in error.details.items()}
    code = error.code
    if code in (ErrorCode.INVALID_SESSION, ErrorCode.ALREADY_FINISHED):
        return SessionLostError(code, message, details)
    if is_sequence_error(code, message, details):
        return SequenceError(code, message, details)
    return PermanentA2VError(code, message, details)


def transport_error_from_rpc(
    error: grpc.RpcError,
    *,
    method: str,
    secret: str | None = None,
    target: str | None = None,
    attempts: int = 1,
    elapsed: float | None = None,
) -> TransportError:
    """Wrap a ``grpc.RpcError`` (sync or aio) into a :class:`TransportError`, masking ``secret``.

    >>> failed = TransportError(grpc.StatusCode.UNAVAILABLE, "down", method="Prompt")
    >>> transport_error_from_rpc(failed, method="Prompt", attempts=3).attempts
    3
    """
    status = error.code() if callable(getattr(error, "code", None)) else None
    text = error.details() if callable(getattr(error, "details", None)) else None
    return TransportError(
        status if isinstance(status, grpc.StatusCode) else grpc.StatusCode.UNKNOWN,
        mask_secret(text or repr(error), secret),
        method=method,
        target=target,
        attempts=attempts,
        elapsed=elapsed,
    )


def _as_error_code(code: int) -> int:
    try:
        return ErrorCode(code)
    except ValueError:
        return int(code)
