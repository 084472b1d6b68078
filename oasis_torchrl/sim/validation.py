"""Checks of A2V request contents; each failure is a :class:`RequestError` naming the problem."""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np

from oasis_torchrl.proto import a2v_pb2, common_pb2
from oasis_torchrl.protocol import CHUNK, MAX_SEED
from oasis_torchrl.sim.encoding import format_name
from oasis_torchrl.sim.errors import RequestError

#: Actions per Infer call, fixed by the protocol.
# "0.0.2", "1.2.3rc1", "0.0.0+unknown", "oasis-torchrl/0.1.0", "v2.1-beta".
_SDK_VERSION = re.compile(r"(?:[A-Za-z][\w.-]{0,63}/)?v?\d{1,6}(?:\.\d{1,6}){0,3}[\w.+-]{0,32}")


def check_sdk_version(version: str) -> None:
    """Reject an empty or unparseable ``client_sdk_version`` (``UNSUPPORTED_SDK_VERSION``).

    Example:
        >>> check_sdk_version("0.0.2"); check_sdk_version("oasis-torchrl/0.1.0")
        >>> check_sdk_version("latest")
        Traceback (most recent call last):
        ...
        oasis_torchrl.sim.errors.RequestError: client_sdk_version 'latest' is not a version ...
    """
    if not version:
        raise RequestError(
            common_pb2.ERROR_CODE_UNSUPPORTED_SDK_VERSION,
            "client_sdk_version is empty; send the client's version, e.g. '0.0.2'",
        )
    if not _SDK_VERSION.fullmatch(version):
        raise RequestError(
            common_pb2.ERROR_CODE_UNSUPPORTED_SDK_VERSION,
            f"client_sdk_version {version[:80]!r} is not a version "
            "(expected e.g. '0.0.2' or 'name/0.1.0')",
        )


def negotiate_format(accepted: Sequence[int], available: Sequence[int]) -> int:
    """The first of the client's ``accepted`` formats (client order) that is ``available``.

    Example:
        >>> from oasis_torchrl.proto import common_pb2 as c
        >>> negotiate_format([c.FRAME_FORMAT_H264, c.FRAME_FORMAT_JPEG], [c.FRAME_FORMAT_VP9,
        ...     c.FRAME_FORMAT_JPEG]) == c.FRAME_FORMAT_JPEG
        True
    """
    for frame_format in accepted:
        if frame_format in available:
            return frame_format
    offered = ", ".join(format_name(f) for f in accepted) or "none"
    supported = ", ".join(format_name(f) for f in available)
    raise RequestError(
        common_pb2.ERROR_CODE_INVALID_FORMAT,
        f"no supported output format among accepted_output_formats ({offered}); "
        f"this server supports {supported}",
    )


def check_prompt(prompt: str, max_chars: int) -> None:
    """Reject a blank prompt or one longer than ``max_chars`` (``INVALID_REQUEST``).

    Example:
        >>> check_prompt("a sunny highway", 2000)
        >>> check_prompt("   ", 2000)
        Traceback (most recent call last):
        ...
        oasis_torchrl.sim.errors.RequestError: prompt is empty; describe the scene to drive in
    """
    if not prompt.strip():
        raise RequestError(
            common_pb2.ERROR_CODE_INVALID_REQUEST, "prompt is empty; describe the scene to drive in"
        )
    if len(prompt) > max_chars:
        raise RequestError(
            common_pb2.ERROR_CODE_INVALID_REQUEST,
            f"prompt has {len(prompt)} characters; the limit is {max_chars}",
        )


def parse_seed(value: str | bytes | None) -> int:
    """The scene seed from ``x-oasis-seed`` metadata: a decimal uint64, 0 when absent.

    Example:
        >>> parse_seed(None), parse_seed("42")
        (0, 42)
        >>> parse_seed("-1")
        Traceback (most recent call last):
        ...
        oasis_torchrl.sim.errors.RequestError: x-oasis-seed must be a decimal integer in ...
    """
    if value is None:
        return 0
    text = value.decode("ascii", "replace") if isinstance(value, bytes) else value
    if text.isascii() and text.isdigit() and len(text) <= 20 and int(text) <= MAX_SEED:
        return int(text)
    raise RequestError(
        common_pb2.ERROR_CODE_INVALID_REQUEST,
        f"x-oasis-seed must be a decimal integer in [0, 2**64 - 1], got {text[:40]!r}",
    )


def actions_to_array(actions: Sequence[a2v_pb2.Action]) -> np.ndarray:
    """The Infer actions as float32 ``[4, 2]`` ``[throttle, steering]``, each finite in [-1, 1].

    Example:
        >>> from oasis_torchrl.proto import a2v_pb2
        >>> actions_to_array([a2v_pb2.Action(throttle=1.0, steering=-0.5)] * 4).shape
        (4, 2)
    """
    if len(actions) != CHUNK:
        raise RequestError(
            common_pb2.ERROR_CODE_INVALID_REQUEST,
            f"Infer takes exactly {CHUNK} actions, got {len(actions)}",
        )
    array = np.array([(a.throttle, a.steering) for a in actions], dtype=np.float32)
    bad = ~(np.isfinite(array) & (np.abs(array) <= 1.0))
    if bad.any():
        index, column = (int(i) for i in np.argwhere(bad)[0])
        name = ("throttle", "steering")[column]
        raise RequestError(
            common_pb2.ERROR_CODE_INVALID_REQUEST,
            f"actions[{index}].{name} must be finite and in [-1, 1], got {array[index, column]}",
        )
    return array
