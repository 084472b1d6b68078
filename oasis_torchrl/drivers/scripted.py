"""Constant, sinusoidal or weaving throttle and steering from a small spec."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from tensordict import TensorDictBase

from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.protocol import CHUNK

Signal = Callable[[np.ndarray], np.ndarray]


SIGNALS = (
    "a number, sine:AMPLITUDE:PERIOD_FRAMES[:OFFSET] or weave:AMPLITUDE:PULSE_FRAMES:GAP_FRAMES"
)

#: The weave's S-curves in turn: out to one side, back, out to the other side, back.
_WEAVE_SIDES = np.array([1.0, -1.0, -1.0, 1.0])


def weave(amplitude: float, pulse: int, gap: int) -> Signal:
    """Blind lane changes: every ``gap`` frames an S-curve (``amplitude`` for ``pulse`` frames,
    then ``-amplitude`` as long), which moves the car sideways and leaves its heading as it was;
    the curves go out to the right, back, out to the left, back. At full speed, 0.088 for 20
    frames moves the car by one 3.2 m lane.

    Example:
        >>> signal = weave(0.1, pulse=2, gap=5)
        >>> signal(np.arange(20)).tolist()[:10]
        [0.1, 0.1, -0.1, -0.1, 0.0, -0.1, -0.1, 0.1, 0.1, 0.0]
    """
    if pulse <= 0 or gap < 2 * pulse:
        raise ValueError(f"a weave needs 0 < pulse and 2 x pulse <= gap, got {pulse} and {gap}")

    def signal(frames: np.ndarray) -> np.ndarray:
        steer = amplitude * _WEAVE_SIDES[(frames // gap) % len(_WEAVE_SIDES)]
        phase = frames % gap
        return np.select([phase < pulse, phase < 2 * pulse], [steer, -steer], 0.0)

    return signal


def _parse_signal(name: str, text: str) -> Signal:
    """A signal of :data:`SIGNALS` (periods, pulses and gaps in frames)."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            level = float(parts[0])
            return lambda frames: np.full(frames.shape, level)
        if parts[0] == "sine" and len(parts) in (3, 4):
            amplitude, period = float(parts[1]), float(parts[2])
            offset = float(parts[3]) if len(parts) == 4 else 0.0
            if period <= 0:
                raise ValueError(f"the period must be positive, got {period}")
            return lambda frames: offset + amplitude * np.sin(2 * np.pi * frames / period)
        if parts[0] == "weave" and len(parts) == 4:
            return weave(float(parts[1]), int(parts[2]), int(parts[3]))
    except ValueError as error:  # a bad number, or a weave's bad pulse and gap: say which
        raise ValueError(f"{name}={text!r}: {error}; expected {SIGNALS}") from None
    raise ValueError(f"{name}={text!r}: expected {SIGNALS}")


class ScriptedDriver(Driver):
    """Open-loop driving from a spec such as ``"throttle=0.5,steering=sine:0.3:40"``.

    Each of ``throttle`` and ``steering`` is a constant, a sine over frames (period in frames,
    20 per second) or a weave (:func:`weave`; e.g. ``steering=weave:0.088:20:100``, blind lane
    changes to either side and back); unset channels are 0. Time counts frames since the driver was
    created, the same for every row.

    Example:
        >>> from tensordict import TensorDict
        >>> driver = ScriptedDriver.from_spec("throttle=0.5,steering=sine:0.2:8")
        >>> chunk = driver(TensorDict(batch_size=[2]))["action"]
        >>> chunk.shape, chunk[0, :, 0].tolist(), round(chunk[0, 2, 1].item(), 3)
        (torch.Size([2, 4, 2]), [0.5, 0.5, 0.5, 0.5], 0.2)
    """

    def __init__(self, throttle: Signal, steering: Signal, *, chunk_actions: bool = True) -> None:
        super().__init__(chunk_actions=chunk_actions)
        self._signals = (throttle, steering)
        self._frame = 0

    @classmethod
    def from_spec(cls, spec: str, *, chunk_actions: bool = True) -> ScriptedDriver:
        """Parse ``name=value`` pairs separated by commas (names: throttle, steering)."""
        signals = {"throttle": "0", "steering": "0"}
        for item in filter(None, (part.strip() for part in spec.split(","))):
            name, sep, value = item.partition("=")
            if not sep or name.strip() not in signals:
                raise ValueError(
                    f"bad driver spec item {item!r}: expected throttle=... or steering=..."
                )
            signals[name.strip()] = value.strip()
        throttle, steering = (_parse_signal(name, text) for name, text in signals.items())
        return cls(throttle, steering, chunk_actions=chunk_actions)

    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """The next 4 frames of the script, the same for every row."""
        frames = self._frame + np.arange(CHUNK)
        self._frame += CHUNK
        chunk = np.stack([signal(frames) for signal in self._signals], axis=-1)
        rows = td.batch_size[0] if td.batch_dims else 1
        return torch.from_numpy(chunk.astype(np.float32)).expand(rows, -1, -1)
