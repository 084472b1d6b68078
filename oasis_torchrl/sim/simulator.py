"""The embedded simulator: prompt + seed to a world, 4 actions to 4 frames per camera.

This is what the embedded A2V server calls. Conventions (shared with the A2V protocol):
cameras ``left_forward``, ``front``, ``right_forward``; actions ``float32 (4, 2)`` of
``[throttle, steering]`` in [-1, 1] (steering + is right); frame ``k`` is the world after action
``k``; same prompt and seed give the same frames and truth, frame for frame.

``step(actions, render=False)`` advances the physics without drawing (``rgb`` is then empty), for
fast tests and privileged data collection; ``step(actions, last_only=True)`` draws only the last
frame, for a client that looks at nothing else.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.proto import sim_pb2
from oasis_torchrl.protocol import CAMERAS, CHUNK, MAX_SEED
from oasis_torchrl.sim.render import Renderer
from oasis_torchrl.sim.scene import OBSTACLE_KINDS, Scene, cached_scene
from oasis_torchrl.sim.vehicle import VehicleParams
from oasis_torchrl.sim.world import FrameTruth, World

__all__ = ["CAMERAS", "FrameTruth", "Simulator", "StepResult"]

logger = logging.getLogger(__name__)

#: Actions per step (one A2V Infer).
#: Spacing of the centreline samples in :meth:`Simulator.scene_proto`, metres.
CENTERLINE_SPACING = 2.0
#: Scenes kept for reuse across resets (building one takes a few tens of milliseconds).
_MIN_SIZE = 8


@dataclass(frozen=True, slots=True)
class StepResult:
    """Frames and truth of one step.

    ``rgb[camera]`` is ``uint8 [4, H, W, 3]`` (C-contiguous; ``[1, H, W, 3]`` when only the last
    frame was rendered, empty ``[0, H, W, 3]`` when none was); ``truth[k]`` is the world after
    action ``k``.

    Example:
        >>> simulator = Simulator(64, 48)
        >>> simulator.reset("rural", seed=1)
        >>> result = simulator.step(np.zeros((4, 2), np.float32))
        >>> result.rgb["front"].shape, len(result.truth)
        ((4, 48, 64, 3), 4)
    """

    rgb: dict[str, np.ndarray]
    truth: tuple[FrameTruth, ...]


def scene_proto(scene: Scene, vehicle: VehicleParams | None = None) -> sim_pb2.SceneResponse:
    """The static world as ``SimService/GetScene`` reports it: centreline samples, road width,
    lanes and their width, obstacles, prompt and seed, and the size of the car driving in it
    (``vehicle``, default :class:`VehicleParams`).

    Example:
        >>> proto = scene_proto(cached_scene("rural road", 3))
        >>> proto.prompt, proto.seed, len(proto.centerline_x) > 100
        ('rural road', 3, True)
    """
    x, y = scene.road.samples(CENTERLINE_SPACING)
    obstacles = scene.obstacles
    vehicle = vehicle or VehicleParams()
    return sim_pb2.SceneResponse(
        prompt=scene.prompt,
        seed=scene.seed,
        centerline_x=x.tolist(),
        centerline_y=y.tolist(),
        road_half_width=scene.style.road_half_width,
        lanes=scene.style.lanes,
        lane_width=scene.style.lane_width,
        ego_length=vehicle.length,
        ego_width=vehicle.width,
        obstacles=[
            sim_pb2.Obstacle(
                kind=OBSTACLE_KINDS[kind],
                x=float(x_),
                y=float(y_),
                heading=float(heading),
                length=float(length),
                width=float(width),
            )
            for kind, x_, y_, heading, length, width in zip(
                obstacles.kind.tolist(),
                obstacles.x,
                obstacles.y,
                obstacles.heading,
                obstacles.length,
                obstacles.width,
                strict=True,
            )
        ],
    )


def _validate_size(name: str, value: int) -> int:
    """``value`` as a pixel count of at least :data:`_MIN_SIZE`, or a clear error."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if value < _MIN_SIZE:
        raise ValueError(f"{name} must be at least {_MIN_SIZE} pixels, got {value}")
    return int(value)


def validate_actions(actions: np.ndarray) -> np.ndarray:
    """``actions`` as float32 ``(4, 2)``, finite and within [-1, 1], or a ValueError naming the
    problem.

    Example:
        >>> validate_actions([[0.5, 0.0]] * 4).dtype
        dtype('float32')
        >>> validate_actions(np.zeros((3, 2)))
        Traceback (most recent call last):
        ...
        ValueError: actions must have shape (4, 2) ([throttle, steering] x 4), got (3, 2)
    """
    try:
        array = np.asarray(actions, dtype=np.float32)
    except (TypeError, ValueError) as error:
        raise ValueError(f"actions must be numeric, got {type(actions).__name__}") from error
    if array.shape != (CHUNK, 2):
        raise ValueError(
            f"actions must have shape ({CHUNK}, 2) ([throttle, steering] x {CHUNK}), "
            f"got {array.shape}"
        )
    if not np.all(np.isfinite(array)):
        raise ValueError(f"actions must be finite, got {array.tolist()}")
    if np.any(np.abs(array) > 1.0):
        raise ValueError(f"actions must be within [-1, 1], got {array.tolist()}")
    return array


class Simulator:
    """A procedural driving world with three cameras.

    Args:
        width: Frame width in pixels (>= 8).
        height: Frame height in pixels (>= 8).
        fps: Frames (and actions) per second; the physics step is ``1 / fps``.

    Example:
        >>> simulator = Simulator(width=96, height=64)
        >>> simulator.reset("urban street at night", seed=3)
        >>> result = simulator.step(np.array([[1.0, 0.0]] * 4, np.float32))
        >>> result.truth[-1].speed > 0, simulator.truth.distance > 0
        (True, True)
    """

    def __init__(self, width: int = 768, height: int = 512, fps: float = 20.0) -> None:
        self._width = _validate_size("width", width)
        self._height = _validate_size("height", height)
        if not isinstance(fps, (int, float)) or not math.isfinite(fps) or fps <= 0:
            raise ValueError(f"fps must be a positive finite number, got {fps!r}")
        self._fps = float(fps)
        self._renderer = Renderer(self._width, self._height)
        self._world: World | None = None
        self._rendered_state = None
        self._depth: dict[str, np.ndarray] | None = None

    @property
    def width(self) -> int:
        """Frame width in pixels."""
        return self._width

    @property
    def height(self) -> int:
        """Frame height in pixels."""
        return self._height

    @property
    def fps(self) -> float:
        """Frames per second (one action per frame)."""
        return self._fps

    @property
    def camera_names(self) -> tuple[str, ...]:
        """The cameras, in stream order."""
        return CAMERAS

    @property
    def scene(self) -> Scene:
        """The current scene (after :meth:`reset`)."""
        return self._require_world().scene

    @property
    def truth(self) -> FrameTruth:
        """Ground truth of the current state."""
        return self._require_world().truth

    @property
    def world(self) -> World:
        """The car in the scene (privileged access for autopilots and tests)."""
        return self._require_world()

    def reset(self, prompt: str, seed: int = 0) -> None:
        """Build (or reuse) the scene of ``prompt`` and ``seed``; the car starts at rest."""
        if not isinstance(prompt, str):
            raise TypeError(f"prompt must be a str, got {type(prompt).__name__}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise TypeError(f"seed must be an int, got {type(seed).__name__}")
        if not 0 <= seed <= MAX_SEED:
            raise ValueError(f"seed must be within [0, 2**64 - 1], got {seed}")
        self.load_scene(cached_scene(prompt, int(seed)))

    def load_scene(self, scene: Scene) -> None:
        """Start over in ``scene`` (e.g. a generated scene with scripted obstacles, see
        :meth:`~oasis_torchrl.sim.scene.Scene.with_obstacles`); the car starts at rest."""
        self._world = World(scene, dt=1.0 / self._fps)
        self._renderer.prepare(scene)
        self._rendered_state = self._world.state
        self._depth = None
        logger.debug("scene %r seed %d (%s)", scene.prompt, scene.seed, scene.style.layout)

    def step(self, actions: np.ndarray, render: bool = True, last_only: bool = False) -> StepResult:
        """Apply 4 actions; return the frames after each (unless ``render`` is false; only the
        last one with ``last_only``) and the truth of every frame.

        After a collision the car stays stopped (``collided`` stays true) until :meth:`reset`.

        Example:
            >>> simulator = Simulator(64, 48)
            >>> simulator.reset("rural", seed=1)
            >>> simulator.step(np.zeros((4, 2), np.float32), last_only=True).rgb["front"].shape
            (1, 48, 64, 3)
        """
        world = self._require_world()
        actions = validate_actions(actions)
        count = (1 if last_only else CHUNK) if render else 0
        rgb = {
            name: np.empty((count, self._height, self._width, 3), dtype=np.uint8)
            for name in CAMERAS
        }
        truth, states, frames = [], [], []
        for throttle, steering in actions:
            truth.append(world.advance(float(throttle), float(steering)))
            states.append(world.state)
            frames.append(world.steps)
        if render:  # all poses in one pass: the renderer's per-call overhead is shared
            self._renderer.render_many(states[-count:], frames[-count:], rgb)
            self._rendered_state = world.state
            self._depth = None
        return StepResult(rgb=rgb, truth=tuple(truth))

    def depth(self) -> dict[str, np.ndarray]:
        """Metric depth ``float32 [H, W]`` per camera of the last rendered frame (distance along
        the camera axis, ``inf`` for sky); the reset pose if nothing was rendered since.

        Computed on the first call after a frame and kept (read-only) for later calls.
        """
        self._require_world()
        if self._depth is None:
            self._depth = self._renderer.depth(self._rendered_state)
            for depth in self._depth.values():
                depth.flags.writeable = False
        return self._depth

    def scene_proto(self) -> sim_pb2.SceneResponse:
        """The static world of the current scene (see :func:`scene_proto`)."""
        world = self._require_world()
        return scene_proto(world.scene, world.params)

    def close(self) -> None:
        """Stop the renderer's threads (idempotent; stepping still works, single-threaded)."""
        self._renderer.close()

    def _require_world(self) -> World:
        if self._world is None:
            raise RuntimeError("Simulator.reset(prompt, seed) must be called before stepping")
        return self._world
