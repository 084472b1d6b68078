"""A2V protocol helpers shared by the sync client and the pool: requests, metadata, checks.

Nothing here does I/O; the transports (blocking stubs in ``sync_client``, asyncio stubs in
``pool``) call these to build requests and to interpret answers the same way.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.client.channel import is_on_this_machine
from oasis_torchrl.client.decoding import DECODABLE_FORMATS
from oasis_torchrl.client.errors import DecartRoboticsError, a2v_error_from_proto
from oasis_torchrl.client.types import FrameFormat, StreamInfo
from oasis_torchrl.proto import a2v_pb2
from oasis_torchrl.protocol import (
    API_KEY_ENV_VAR,
    API_KEY_METADATA,
    CHUNK,
    MAX_SEED,
    SEED_METADATA,
    SESSION_TARGET_METADATA,
)

Metadata = tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class SessionInfo:
    """What Initialize established: session id, negotiated format, streams, pinning target.

    >>> SessionInfo("s1", FrameFormat.VP9, (), None).output_format.name
    'VP9'
    """

    session_id: str
    output_format: int
    streams: tuple[StreamInfo, ...]
    session_target: str | None


def missing_api_key_error() -> DecartRoboticsError:
    """The error for a call that needs an API key but has none (raised before any request).

    >>> "DECART_API_KEY" in str(missing_api_key_error())
    True
    """
    return DecartRoboticsError(
        "A Decart API key is required. Pass api_key=... or set the "
        f"{API_KEY_ENV_VAR} environment variable."
    )


def call_metadata(api_key: str | None, session_target: str | None = None) -> Metadata:
    """Metadata sent on every call: API key, then the session pinning target if any.

    >>> call_metadata("k", "node-3")
    (('x-api-key', 'k'), ('x-session-target', 'node-3'))
    """
    metadata: list[tuple[str, str]] = []
    if api_key:
        metadata.append((API_KEY_METADATA, api_key))
    if session_target:
        metadata.append((SESSION_TARGET_METADATA, session_target))
    return tuple(metadata)


def prompt_metadata(metadata: Metadata, seed: int | None) -> Metadata:
    """Session metadata plus the ``x-oasis-seed`` of a Prompt (omitted when ``seed`` is None).

    >>> prompt_metadata((), 7)
    (('x-oasis-seed', '7'),)
    """
    if seed is None:
        return metadata
    return (*metadata, (SEED_METADATA, str(validate_seed(seed))))


def validate_seed(seed: int) -> int:
    """Check a world seed is an integer in the uint64 range.

    >>> validate_seed(-1)
    Traceback (most recent call last):
    ...
    ValueError: seed must be an int in [0, 2**64 - 1], got -1
    """
    if (
        isinstance(seed, bool)
        or not isinstance(seed, (int, np.integer))
        or not 0 <= seed <= MAX_SEED
    ):
        raise ValueError(f"seed must be an int in [0, 2**64 - 1], got {seed!r}")
    return int(seed)


def session_target_from(initial_metadata: Iterable[tuple[str, str | bytes]]) -> str | None:
    """The ``x-session-target`` value of Initialize's initial metadata (str or bytes), if any.

    >>> session_target_from([("x-session-target", b"node-3")])
    'node-3'
    """
    for key, value in initial_metadata:
        if key == SESSION_TARGET_METADATA:
            return value.decode() if isinstance(value, bytes) else value
    return None


def accepted_format_list(
    accepted_formats: Sequence[int] | None, endpoint: str | None
) -> tuple[FrameFormat, ...]:
    """Validate the formats a client offers: non-empty, decodable, no duplicates. None offers
    raw RGB first to a server on this machine (no codec for frames that never leave it), then
    VP9 and JPEG (only those to any other server). ``endpoint`` None is a server the client
    starts itself, on this machine.

    >>> accepted_format_list([3, 1], "https://oasis-grpc.decart.ai")
    (<FrameFormat.VP9: 3>, <FrameFormat.JPEG: 1>)
    >>> accepted_format_list(None, "http://127.0.0.1:50051")[0].name
    'RAW_RGB24'
    """
    if accepted_formats is None:
        nearby = endpoint is None or is_on_this_machine(endpoint)
        local = (FrameFormat.RAW_RGB24,) if nearby else ()
        accepted_formats = (*local, FrameFormat.VP9, FrameFormat.JPEG)
    formats = tuple(FrameFormat(value) for value in accepted_formats)
    unsupported = [f.name for f in formats if f not in DECODABLE_FORMATS]
    if not formats or unsupported or len(set(formats)) != len(formats):
        raise ValueError(
            "accepted_formats must be a non-empty, duplicate-free selection of "
            f"{[f.name for f in DECODABLE_FORMATS]}, got {[f.name for f in formats]}"
        )
    return formats


def initialize_request(
    sdk_version: str, api_key: str, accepted_formats: Sequence[FrameFormat]
) -> a2v_pb2.InitializeRequest:
    """Build an InitializeRequest.

    >>> initialize_request("0.0.2", "k", [FrameFormat.VP9]).accepted_output_formats
    [3]
    """
    return a2v_pb2.InitializeRequest(
        client_sdk_version=sdk_version,
        api_key=api_key,
        accepted_output_formats=[int(f) for f in accepted_formats],
    )


def infer_request(session_id: str, sequence_num: int, actions: np.ndarray) -> a2v_pb2.InferRequest:
    """Build an InferRequest from a validated ``(4, 2)`` action chunk.

    >>> import numpy as np
    >>> len(infer_request("s", 0, np.zeros((4, 2), np.float32)).actions)
    4
    """
    return a2v_pb2.InferRequest(
        session_id=session_id,
        sequence_num=sequence_num,
        actions=[a2v_pb2.Action(throttle=float(t), steering=float(s)) for t, s in actions.tolist()],
    )


def raise_if_error(response: object, secret: str | None) -> None:
    """Raise the response's in-band error (as an A2VError subclass), if it has one.

    >>> raise_if_error(a2v_pb2.PromptResponse(), "k")
    """
    if response.HasField("error"):
        raise a2v_error_from_proto(response.error, secret)


def parse_session(
    response: a2v_pb2.InitializeResponse, initial_metadata: Iterable[tuple[str, str | bytes]]
) -> SessionInfo:
    """Summarise a successful InitializeResponse and its initial metadata.

    >>> response = a2v_pb2.InitializeResponse(session_id="s", output_format=3)
    >>> parse_session(response, [("x-session-target", "n1")]).session_target
    'n1'
    """
    return SessionInfo(
        session_id=response.session_id,
        output_format=_as_format(response.output_format),
        streams=tuple(
            StreamInfo(name=s.name, sensor_type=s.type, height=s.height, width=s.width)
            for s in response.streams
        ),
        session_target=session_target_from(initial_metadata),
    )


def check_session(
    info: SessionInfo, *, accepted_formats: Sequence[int], required_streams: Sequence[str]
) -> None:
    """Raise if the server advertised too few streams or chose a format the client refused.

    >>> info = SessionInfo("s", FrameFormat.JPEG, (), None)
    >>> check_session(info, accepted_formats=[FrameFormat.VP9], required_streams=[])
    Traceback (most recent call last):
    ...
    oasis_torchrl.client.errors.DecartRoboticsError: A2V server negotiated output format JPEG, \
but this client accepted only ['VP9']
    """
    missing = set(required_streams) - {stream.name for stream in info.streams}
    if missing:
        raise DecartRoboticsError(
            "A2V server did not advertise required streams: " + ", ".join(sorted(missing))
        )
    if info.output_format not in accepted_formats:
        raise DecartRoboticsError(
            f"A2V server negotiated output format {format_name(info.output_format)}, "
            f"but this client accepted only {[FrameFormat(f).name for f in accepted_formats]}"
        )


def validate_action_chunk(actions: Iterable[Iterable[float]], name: str = "actions") -> np.ndarray:
    """Check one action chunk locally: shape ``(4, 2)``, finite, inside [-1, 1].

    >>> validate_action_chunk([[0.0, 0.0]] * 4).shape
    (4, 2)
    >>> validate_action_chunk([[2.0, 0.0]] * 4)
    Traceback (most recent call last):
    ...
    ValueError: actions must be in [-1, 1]
    """
    array = np.asarray(actions if isinstance(actions, np.ndarray) else list(actions), np.float32)
    return _check_actions(array, (CHUNK, 2), name)


def validate_action_batch(actions: object, rows: Sequence[int]) -> np.ndarray:
    """Check a pool's action batch: float32 ``[n, 4, 2]`` for the ``n`` selected rows.

    Errors name the offending pool row.

    >>> import numpy as np
    >>> bad = np.zeros((2, 4, 2), np.float32); bad[1, 0, 0] = np.nan
    >>> validate_action_batch(bad, [0, 5])
    Traceback (most recent call last):
    ...
    ValueError: actions for row 5 must be finite
    """
    array = np.asarray(actions, dtype=np.float32)
    expected = (len(rows), CHUNK, 2)
    if array.shape != expected:
        raise ValueError(f"actions must have shape {expected}, got {array.shape}")
    bad_rows = ~(np.isfinite(array) & (np.abs(array) <= 1.0)).all(axis=(1, 2))
    for position in np.flatnonzero(bad_rows):
        _check_actions(array[position], expected[1:], f"actions for row {rows[position]}")
    return array


def _check_actions(array: np.ndarray, shape: tuple[int, ...], name: str) -> np.ndarray:
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite")
    if np.any(np.abs(array) > 1.0):
        raise ValueError(f"{name} must be in [-1, 1]")
    return array


def _as_format(value: int) -> int:
    try:
        return FrameFormat(value)
    except ValueError:
        return int(value)


def format_name(value: int) -> str:
    """Readable name of a frame format value.

    >>> format_name(3), format_name(42)
    ('VP9', '<unknown format 42>')
    """
    value = _as_format(value)
    return value.name if isinstance(value, FrameFormat) else f"<unknown format {value!r}>"
