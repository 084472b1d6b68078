"""Public value types of the client layer.

``StreamInfo``, ``A2VResult`` and ``FrameConsumer`` have the same shapes as the official SDK's.
``FrameFormat``, ``SessionStatus`` and ``PoolStep`` are this project's additions.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from oasis_torchrl.protocol import FrameFormat

VP9 = FrameFormat.VP9
JPEG = FrameFormat.JPEG


@dataclass(frozen=True, slots=True)
class StreamInfo:
    """One output stream the server advertised at Initialize.

    >>> StreamInfo(name="front", sensor_type=1, height=512, width=768).width
    768
    """

    name: str
    sensor_type: int
    height: int
    width: int


@dataclass(frozen=True, slots=True)
class A2VResult:
    """Decoded result of one Infer call: frames per stream, in time order.

    >>> A2VResult(sequence_num=0, frames={}, streams=()).sequence_num
    0
    """

    sequence_num: int
    frames: dict[str, list[np.ndarray]]
    streams: tuple[StreamInfo, ...]


@runtime_checkable
class FrameConsumer(Protocol):
    """Receives generated frames as a client produces them (e.g. a live preview).

    ``submit`` gets every decoded chunk, ``new_clip`` marks a new prompt. Both must return quickly.

    >>> class Counter:
    ...     def submit(self, frames): pass
    ...     def new_clip(self): pass
    >>> isinstance(Counter(), FrameConsumer)
    True
    """

    def submit(self, frames: Mapping[str, Sequence[np.ndarray]]) -> None:
        """Take one chunk of frames: stream name -> frames in time order."""
        ...

    def new_clip(self) -> None:
        """Mark a clip boundary: the following frames belong to a new prompt."""
        ...


class ServerHandle(Protocol):
    """A server a :class:`~oasis_torchrl.client.SessionPool` starts with itself and stops when it
    closes (the embedded server's launchers are such handles). ``endpoint`` and ``api_key`` are
    read after :meth:`start`; pickling a handle must drop any running server."""

    @property
    def endpoint(self) -> str:
        """The endpoint URL clients dial."""

    @property
    def api_key(self) -> str:
        """A key the server accepts."""

    def start(self) -> object:
        """Start serving (idempotent)."""

    def stop(self) -> None:
        """Stop serving (idempotent)."""


class SessionStatus(enum.IntEnum):
    """What happened to one pool row during a step.

    ``OK``: the step ran as asked. ``RESTARTED``: the row's rollout had to be restarted (re-prompt
    with its stored prompt and seed, one all-zero chunk); its frames are the new clip's first.
    ``LOST``: the row could not be served; its frames are zeros and its error says why.

    >>> SessionStatus(1).name
    'RESTARTED'
    """

    OK = 0
    RESTARTED = 1
    LOST = 2


@dataclass
class PoolStep:
    """The outcome of one pool step for the selected rows (``n`` of them).

    >>> import numpy as np
    >>> step = PoolStep(frames={}, truth=None, status=np.zeros(2, np.int8), errors=[None, None],
    ...                 sequence_nums=np.zeros(2, np.int64),
    ...                 expert=np.full((2, 4, 2), np.nan, np.float32))
    >>> step.status.tolist()
    [0, 0]
    """

    frames: dict[str, np.ndarray]
    """stream -> uint8 ``[n, F, H, W, 3]``, one array per stream; F is 4, or 1 for a pool built
    with ``frames="last"`` (the chunk's last frame)."""
    truth: np.ndarray | None
    """float64 ``[n, 4, K]`` ground truth in ``TRUTH_FIELDS`` order (NaN where missing), or None."""
    status: np.ndarray
    """int8 ``[n]`` :class:`SessionStatus` per row."""
    errors: list[Exception | None]
    """Per row, the error behind RESTARTED or LOST (None when OK)."""
    sequence_nums: np.ndarray
    """int64 ``[n]`` sequence number of each row's returned chunk (-1 when LOST)."""
    expert: np.ndarray
    """float32 ``[n, 4, 2]``: the embedded server's expert's next chunk from each row's new
    state (its autopilot's ``[throttle, steering]`` x 4); NaN where the server sends none."""
