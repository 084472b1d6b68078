"""Drivers for recording: TorchRL-policy-like callables ``td -> td`` that set ``"action"``.

- :class:`Autopilot`: the privileged expert of the embedded simulator. It works from the
  TensorDict alone: the row's ``"prompt"`` and ``"episode_seed"`` rebuild the (deterministic)
  world with :func:`~oasis_torchrl.sim.scene.build_scene`, and the row's ground truth
  ``("truth", field)`` places the car in it. It keeps to the freest lane, changes lanes around
  obstacles, and brakes when no lane is free.
- :class:`ScriptedDriver`: constant or sinusoidal throttle and steering from a small spec.
- :class:`PolicyDriver`: a saved policy (TorchScript or ``torch.save``d module).

Every driver returns action chunks ``[N, 4, 2]`` (or ``[N, 2]`` for an env built with
``chunk_actions=False``).
"""

from __future__ import annotations

import functools
import logging
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tensordict import NonTensorData, TensorDictBase
from tensordict.nn import TensorDictModuleBase

from oasis_torchrl.client.types import DEFAULT_REQUIRED_STREAMS
from oasis_torchrl.client.wire import ACTIONS_PER_CHUNK
from oasis_torchrl.sim.scene import Scene, build_scene
from oasis_torchrl.sim.vehicle import VehicleParams

logger = logging.getLogger(__name__)

TRUTH = "truth"
_TRUTH_USED = ("x", "y", "heading", "speed", "progress", "lateral_offset", "collided")


class Driver(ABC):
    """Base of the drivers: computes ``[N, 4, 2]`` chunks and writes them to ``"action"``.

    Args:
        chunk_actions: write ``[N, 4, 2]`` chunks; if false, ``[N, 2]`` (the chunk's first).
    """

    def __init__(self, *, chunk_actions: bool = True) -> None:
        self.chunk_actions = chunk_actions

    @abstractmethod
    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """float32 ``[N, 4, 2]`` action chunks for the observation rows of ``td``."""

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        """Set ``td["action"]`` and return ``td`` (as a TorchRL policy does)."""
        chunk = self.chunks(td).to(torch.float32).clamp(-1.0, 1.0)
        td.set("action", chunk if self.chunk_actions else chunk[:, 0].contiguous())
        return td


# -- autopilot ----------------------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def cached_scene(prompt: str, seed: int) -> Scene:
    """The world of ``(prompt, seed)``, built once per process (building is deterministic).

    Example:
        >>> cached_scene("rural road", 3) is cached_scene("rural road", 3)
        True
    """
    return build_scene(prompt, seed)


@dataclass(frozen=True)
class AutopilotSettings:
    """Tuning of :class:`Autopilot` (metres, seconds, m/s).

    Example:
        >>> AutopilotSettings().cruise_speed(14.0)
        9.8
    """

    speed_fraction: float = 0.7
    max_speed: float = 12.0
    lookahead_time: float = 0.8
    min_lookahead: float = 6.0
    scan_time: float = 3.5
    min_scan: float = 25.0
    clearance: float = 0.5
    stop_gap: float = 4.0
    deceleration: float = 3.0
    speed_gain: float = 0.6

    def cruise_speed(self, speed_limit: float) -> float:
        """Target speed on a free road."""
        return round(min(self.speed_fraction * speed_limit, self.max_speed), 6)


def lane_gap(
    scene: Scene,
    s: float,
    lane_offset: float,
    reach: float,
    car: VehicleParams,
    clearance: float = AutopilotSettings.clearance,
) -> float:
    """Free distance ahead of the car's front in the lane centred at ``lane_offset``.

    An obstacle is in the lane if it comes within ``clearance`` of the car's sides there.
    Obstacles alongside the car count (gap 0), so a lane is only free if the car fits into it
    now. Returns ``reach`` when nothing is in the way within it.

    Example:
        >>> scene = build_scene("highway", 0)
        >>> lane_gap(scene, 0.0, scene.style.lane_offset(0), 30.0, VehicleParams())
        30.0
    """
    obstacles = scene.obstacles
    near = obstacles.between(s - 15.0, s + reach + 15.0)
    half = car.length / 2
    in_lane = np.abs(obstacles.d[near] - lane_offset) < (
        obstacles.half_across[near] + car.width / 2 + clearance
    )
    rear = obstacles.s[near] - obstacles.half_along[near] - (s + half)
    front = obstacles.s[near] + obstacles.half_along[near] - (s - half)
    blocking = in_lane & (front > 0.0)
    if not blocking.any():
        return reach
    return float(np.clip(rear[blocking].min(), 0.0, reach))


def _choose_lane(
    scene: Scene, s: float, d: float, reach: float, car: VehicleParams, clearance: float
) -> int:
    """The current lane while it is free, else the adjacent lane with the most room."""
    style = scene.style
    offsets = [style.lane_offset(lane) for lane in range(style.lanes)]
    current = int(np.argmin([abs(d - offset) for offset in offsets]))
    candidates = [lane for lane in (current, current - 1, current + 1) if 0 <= lane < style.lanes]
    gaps = {lane: lane_gap(scene, s, offsets[lane], reach, car, clearance) for lane in candidates}
    if gaps[current] >= reach:
        return current
    return max(candidates, key=lambda lane: (gaps[lane], lane == current))


def _pursuit_steering(
    scene: Scene,
    truth: dict[str, float],
    target_offset: float,
    lookahead: float,
    car: VehicleParams,
) -> float:
    """Pure pursuit towards the target lane's centre ``lookahead`` metres ahead."""
    x, y, _ = scene.road.pose_at(truth["progress"] + lookahead, target_offset)
    dx, dy = float(x) - truth["x"], float(y) - truth["y"]
    alpha = math.remainder(math.atan2(dy, dx) - truth["heading"], math.tau)
    curvature = 2.0 * math.sin(alpha) / max(math.hypot(dx, dy), 1e-3)
    wheel_angle = math.atan(curvature * car.wheelbase)
    return -wheel_angle / car.max_steer  # steering + turns right (clockwise)


def autopilot_action(
    scene: Scene, truth: dict[str, float], settings: AutopilotSettings = AutopilotSettings()
) -> tuple[float, float]:
    """``(throttle, steering)`` of the expert for one car state.

    Args:
        scene: the world the car drives in.
        truth: ground-truth fields of the current frame (``x``, ``y``, ``heading``, ``speed``,
            ``progress``, ``lateral_offset``, ``collided``).
        settings: tuning.

    Example:
        >>> scene = build_scene("highway", 0)
        >>> x, y, heading = scene.road.pose_at(0.0, scene.style.lane_offset(0))
        >>> truth = dict(x=float(x), y=float(y), heading=float(heading), speed=0.0,
        ...              progress=0.0, lateral_offset=scene.style.lane_offset(0), collided=0.0)
        >>> throttle, steering = autopilot_action(scene, truth)
        >>> throttle > 0.5 and abs(steering) < 0.1
        True
    """
    if truth["collided"] > 0.5:
        return 0.0, 0.0
    car = VehicleParams(max_speed=scene.style.speed_limit)
    speed = max(truth["speed"], 0.0)
    s, d = truth["progress"], truth["lateral_offset"]
    reach = max(settings.min_scan, settings.scan_time * speed)
    lane = _choose_lane(scene, s, d, reach, car, settings.clearance)
    style = scene.style
    # The car must also stop for anything in the lanes its body still overlaps.
    touches = style.lane_width / 2 + car.width / 2
    lanes = {lane} | {k for k in range(style.lanes) if abs(d - style.lane_offset(k)) < touches}
    gap = min(
        lane_gap(scene, s, style.lane_offset(k), reach, car, settings.clearance) for k in lanes
    )
    room = max(gap - settings.stop_gap, 0.0)
    target = min(
        settings.cruise_speed(style.speed_limit), math.sqrt(2 * settings.deceleration * room)
    )
    throttle = float(np.clip(settings.speed_gain * (target - speed), -1.0, 1.0))
    lookahead = max(settings.min_lookahead, settings.lookahead_time * speed)
    steering = _pursuit_steering(scene, truth, style.lane_offset(lane), lookahead, car)
    return throttle, float(np.clip(steering, -1.0, 1.0))


def _row_strings(td: TensorDictBase, key: str) -> list[str]:
    value = td.get(key, None)
    if value is None:
        raise KeyError(f"the observation has no {key!r}")
    if isinstance(value, NonTensorData):
        value = value.data
    if isinstance(value, str):
        return [value] * td.batch_size[0]
    return list(value.tolist())


class Autopilot(Driver):
    """The privileged expert: drives from ground truth and the world rebuilt from the row.

    Needs the embedded server's ground truth (``("truth", field)``); every action of the chunk
    is the same (the expert looks once per chunk, like a policy).

    Args:
        settings: tuning.
        chunk_actions: see :class:`Driver`.

    Example:
        >>> from oasis_torchrl.envs import OasisEnv  # doctest: +SKIP
        >>> env = OasisEnv("local", num_envs=2)  # doctest: +SKIP
        >>> rollout = env.rollout(20, Autopilot())  # doctest: +SKIP
    """

    def __init__(
        self, settings: AutopilotSettings | None = None, *, chunk_actions: bool = True
    ) -> None:
        super().__init__(chunk_actions=chunk_actions)
        self.settings = settings or AutopilotSettings()

    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """One expert action per row, repeated over the chunk."""
        missing = [name for name in _TRUTH_USED if (TRUTH, name) not in td.keys(True)]
        if missing:
            raise KeyError(
                f"the autopilot needs ground truth {[(TRUTH, m) for m in missing]}, which only "
                "the embedded server (endpoint 'local') sends"
            )
        truth = {name: td.get((TRUTH, name))[:, -1].double().cpu().numpy() for name in _TRUTH_USED}
        prompts = _row_strings(td, "prompt")
        seeds = td.get("episode_seed").reshape(-1).tolist()
        actions = np.zeros((len(prompts), 2), np.float32)
        for row, (prompt, seed) in enumerate(zip(prompts, seeds, strict=True)):
            state = {name: float(values[row]) for name, values in truth.items()}
            if all(math.isfinite(value) for value in state.values()):
                actions[row] = autopilot_action(
                    cached_scene(prompt, int(seed)), state, self.settings
                )
        return torch.from_numpy(actions).unsqueeze(1).expand(-1, ACTIONS_PER_CHUNK, 2)


# -- scripted driver ----------------------------------------------------------------------

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
        frames = self._frame + np.arange(ACTIONS_PER_CHUNK)
        self._frame += ACTIONS_PER_CHUNK
        chunk = np.stack([signal(frames) for signal in self._signals], axis=-1)
        rows = td.batch_size[0] if td.batch_dims else 1
        return torch.from_numpy(chunk.astype(np.float32)).expand(rows, -1, -1)


# -- saved policy ---------------------------------------------------------------------------


def load_module(path: str | Path) -> torch.nn.Module:
    """A TorchScript archive or a ``torch.save``d module (unpickling runs code: trust the file).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "linear.pt"
        >>> torch.jit.save(torch.jit.script(torch.nn.Linear(2, 8)), path)
        >>> isinstance(load_module(path), torch.jit.ScriptModule)
        True
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"policy file {path} does not exist")
    try:
        return torch.jit.load(str(path), map_location="cpu")
    except RuntimeError:
        module = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(module, torch.nn.Module):
        raise TypeError(f"{path} holds a {type(module).__name__}, not a torch module")
    return module


def _as_chunks(action: torch.Tensor, rows: int) -> torch.Tensor:
    """A policy output ``[N, 4, 2]``, ``[N, 8]`` or ``[N, 2]`` as ``[N, 4, 2]`` chunks."""
    action = action.detach().to("cpu", torch.float32)
    if action.shape in ((rows, ACTIONS_PER_CHUNK, 2), (rows, ACTIONS_PER_CHUNK * 2)):
        return action.reshape(rows, ACTIONS_PER_CHUNK, 2)
    if action.shape == (rows, 2):
        return action.unsqueeze(1).expand(-1, ACTIONS_PER_CHUNK, 2)
    raise ValueError(
        f"policy action must be [{rows}, 4, 2], [{rows}, 8] or [{rows}, 2], "
        f"got {list(action.shape)}"
    )


class PolicyDriver(Driver):
    """Drives with a torch policy.

    A TensorDict module (``tensordict.nn``) is called on the observation and must set
    ``"action"``; a plain module (e.g. TorchScript) is called with the tensors at ``in_keys``
    (default: ``("pixels", camera)`` of ``left_forward``, ``front``, ``right_forward`` as far
    as present, uint8 as the env gives them, then ``"state"``) and returns the actions.
    Outputs are clamped to [-1, 1]; NaN is an error.

    Args:
        module: the policy.
        in_keys: inputs of a plain module.
        chunk_actions: see :class:`Driver`.

    Example:
        >>> from tensordict import TensorDict
        >>> class Half(torch.nn.Module):
        ...     def forward(self, state):
        ...         return state * 0.5
        >>> driver = PolicyDriver(Half(), in_keys=["state"])
        >>> driver(TensorDict(state=torch.ones(3, 2), batch_size=[3]))["action"].shape
        torch.Size([3, 4, 2])
    """

    def __init__(
        self,
        module: torch.nn.Module,
        in_keys: Sequence[str | tuple[str, ...]] | None = None,
        *,
        chunk_actions: bool = True,
    ) -> None:
        super().__init__(chunk_actions=chunk_actions)
        self.module = module.eval()
        self.in_keys = list(in_keys) if in_keys is not None else None

    @classmethod
    def load(cls, path: str | Path, **kwargs: object) -> PolicyDriver:
        """Load a saved policy (see :func:`load_module`)."""
        return cls(load_module(path), **kwargs)

    def _inputs(self, td: TensorDictBase) -> list[torch.Tensor]:
        if self.in_keys is not None:
            return [td.get(key) for key in self.in_keys]
        keys = td.keys(True)
        pixels = [("pixels", c) for c in DEFAULT_REQUIRED_STREAMS if ("pixels", c) in keys]
        return [td.get(key) for key in pixels] + [td.get("state")]

    @torch.no_grad()
    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """Run the policy on ``td``."""
        if isinstance(self.module, TensorDictModuleBase):
            action = self.module(td.clone(False)).get("action")
        else:
            action = self.module(*self._inputs(td))
        chunk = _as_chunks(action, td.batch_size[0])
        if torch.isnan(chunk).any():
            raise ValueError("the policy returned NaN actions")
        return chunk
