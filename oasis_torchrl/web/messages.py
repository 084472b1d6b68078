"""The page's messages to the server, checked: anything else is refused by name.

A message is one JSON object with a ``type``:

==============  ================================================  ==================================
type            fields                                            what it does
==============  ================================================  ==================================
``control``     ``throttle``, ``steering`` in [-1, 1], ``seq``    the person's input (held until
                (an increasing int the page stamps it with)       the next one)
``record``      ``command``: ``start`` | ``stop`` |               start, save or drop an episode;
                ``discard`` | ``crash``                           ``crash`` marks a crash: the
                                                                  episode ends at the next chunk,
                                                                  saved with ``next.crash`` set
``takeover``    ``human``: bool                                   the person drives, or hands back
                                                                  to the policy
``reset``                                                         a new scene (a new episode)
``replay``      ``episode``: int                                  stream a saved episode's frames
==============  ================================================  ==================================

Refusals (:class:`Refused`) carry a stable ``name`` the page shows and tests match on.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

MAX_MESSAGE_BYTES = 4096
RECORD_COMMANDS = ("start", "stop", "discard", "crash")


class Refused(Exception):
    """A message or request the session does not carry out; ``name`` says why.

    Example:
        >>> Refused("second_driver", "another page drives").as_message()["error"]
        'second_driver'
    """

    def __init__(self, name: str, message: str) -> None:
        super().__init__(f"{name}: {message}")
        self.name = name
        self.message = message

    def as_message(self) -> dict[str, str]:
        """The JSON object sent back to the page."""
        return {"type": "error", "error": self.name, "message": self.message}


@dataclass(frozen=True)
class Control:
    """The person's input: ``throttle`` (+ forward) and ``steering`` (- left, + right)."""

    throttle: float
    steering: float
    seq: int


@dataclass(frozen=True)
class Record:
    """Start, stop (save) or discard an episode, or mark a crash in it."""

    command: str


@dataclass(frozen=True)
class Takeover:
    """The person drives (``human=True``) or hands back to the policy."""

    human: bool


@dataclass(frozen=True)
class Reset:
    """A new scene."""


@dataclass(frozen=True)
class Replay:
    """Stream the frames of saved episode ``episode``."""

    episode: int


Message = Control | Record | Takeover | Reset | Replay


def _unit(fields: dict[str, Any], name: str) -> float:
    value = fields.get(name)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise Refused("malformed_message", f"{name} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise Refused("action_not_finite", f"{name} must be finite, got {value!r}")
    if not -1.0 <= value <= 1.0:
        raise Refused("action_out_of_range", f"{name} must be in [-1, 1], got {value!r}")
    return float(value)


def _int(fields: dict[str, Any], name: str) -> int:
    value = fields.get(name)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise Refused("malformed_message", f"{name} must be a non-negative integer, got {value!r}")
    return value


def parse_message(text: str | bytes) -> Message:
    """Check one message from the page.

    Raises:
        Refused: ``malformed_message`` (not a JSON object, a field missing or of a wrong type,
            too long), ``unknown_type``, ``action_not_finite``, ``action_out_of_range``.

    Example:
        >>> parse_message('{"type": "control", "throttle": 0.5, "steering": -1, "seq": 3}')
        Control(throttle=0.5, steering=-1.0, seq=3)
        >>> parse_message('{"type": "control", "throttle": 2, "steering": 0, "seq": 4}')
        Traceback (most recent call last):
        ...
        oasis_torchrl.web.messages.Refused: action_out_of_range: throttle must be in [-1, 1], got 2
        >>> parse_message('{"type": "control", "throttle": NaN, "steering": 0, "seq": 5}').seq
        Traceback (most recent call last):
        ...
        oasis_torchrl.web.messages.Refused: action_not_finite: throttle must be finite, got nan
    """
    if len(text) > MAX_MESSAGE_BYTES:
        raise Refused("malformed_message", f"longer than {MAX_MESSAGE_BYTES} bytes")
    try:
        fields = json.loads(text)
    except (ValueError, UnicodeDecodeError) as error:
        raise Refused("malformed_message", f"not JSON ({error})") from None
    if not isinstance(fields, dict):
        raise Refused("malformed_message", "a message is a JSON object with a 'type'")
    kind = fields.get("type")
    if kind == "control":
        return Control(_unit(fields, "throttle"), _unit(fields, "steering"), _int(fields, "seq"))
    if kind == "record":
        command = fields.get("command")
        if command not in RECORD_COMMANDS:
            raise Refused("malformed_message", f"command must be one of {RECORD_COMMANDS}")
        return Record(command)
    if kind == "takeover":
        if not isinstance(fields.get("human"), bool):
            raise Refused("malformed_message", "human must be true or false")
        return Takeover(fields["human"])
    if kind == "reset":
        return Reset()
    if kind == "replay":
        return Replay(_int(fields, "episode"))
    raise Refused("unknown_type", f"unknown message type {kind!r}")
