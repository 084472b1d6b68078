"""Constant or sinusoidal throttle and steering from a small spec."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from tensordict import TensorDictBase

from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.protocol import CHUNK

Signal = Callable[[np.ndarray], np.ndarray]


def _parse_signal(name: str, text: str) -> Signal:
    """``"0.5"`` (constant) or ``"sine:AMPLITUDE:PERIOD[:OFFSET]"`` (period in frames)."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            level = float(parts[0])
            return lambda frames: np.full(frames.shape, level)
        if parts[0] == "sine" and len(parts) in (3, 4):
            amplitude, period = float(parts[1]), float(parts[2])
            offset = float(parts[3]) if len(parts) == 4 else 0.0
            if period <= 0:
                raise ValueError
            return lambda frames: offset + amplitude * np.sin(2 * np.pi * frames / period)
    except ValueError:
        pass
    raise ValueError(f"{name}={text!r}: expected a number or sine:AMPLITUDE:PERIOD_FRAMES[:OFFSET]")


class ScriptedDriver(Driver):
    """Open-loop driving from a spec such as ``"throttle=0.5,steering=sine:0.3:40"``.

    Each of ``throttle`` and ``steering`` is a constant or a sine over frames (period in
    frames, 20 per second); unset channels are 0. Time counts frames since the driver was
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
