"""One action per frame over the chunked world model: the bridge LeRobot's loops need.

LeRobot's tools (``lerobot-record``, ``-replay``, ``-eval``, ``-rollout``, the async robot
client) send one action per tick at the dataset's fps (20 for the world model) and read one
observation per tick; the A2V protocol takes 4 actions per Infer and answers with their 4
frames. :class:`FrameStepper` bridges the two by *sample and hold*: each tick's action is
buffered and the 4th action of a chunk sends the chunk (one Infer per row, all rows at once);
each tick observes the newest frames the world has produced and, as state, the last action sent.
For chunk ``c`` (actions ``a[4c] .. a[4c+3]``, frames ``f[4c] .. f[4c+3]``, frame ``k`` being the
world after action ``k``):

===========  ==================================  ===========  ===========  =====================
tick         frames observed                     state        action       the world
===========  ==================================  ===========  ===========  =====================
``4c``       ``f[4c-1]`` (the previous chunk's)  ``a[4c-1]``  ``a[4c]``    buffers
``4c+1``     ``f[4c-1]``                         ``a[4c]``    ``a[4c+1]``  buffers
``4c+2``     ``f[4c-1]``                         ``a[4c+1]``  ``a[4c+2]``  buffers
``4c+3``     ``f[4c-1]``                         ``a[4c+2]``  ``a[4c+3]``  Infer: ``f[4c..4c+3]``,
                                                                           reward, end
===========  ==================================  ===========  ===========  =====================

After a reset the frames are those of the reset's all-zero chunk and the state is zero. Why
this bridge: the world cannot show a frame before it has all 4 actions of its chunk, so no
per-frame loop can see ``f[4c]`` before deciding ``a[4c+1]``. Holding the newest frame keeps
every tick's row in the project's dataset convention (the row's action is the one applied next,
the state the action before it), and at each chunk boundary the row is exactly one of the
project's own frame rows (the frame right before the action). A policy that plans chunks of a
multiple of 4 actions therefore always plans on exactly what it was trained on; the
alternative, handing the 4 frames out one per tick, would show every tick a frame 3 frames
older than the dataset convention. The cost: a person sees a new frame every 4 ticks (5 per
second), 0 to 3 frames after their action.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase
from torchrl.envs.utils import step_mdp

from oasis_torchrl.protocol import ACTION_DIM, CHUNK


@dataclass(frozen=True)
class FrameObservation:
    """What every row sees at one tick: ``pixels[camera]`` uint8 ``[N, H, W, 3]`` and
    ``state`` float32 ``[N, 2]`` (the last action sent)."""

    pixels: dict[str, np.ndarray]
    state: np.ndarray


@dataclass(frozen=True)
class FrameStep:
    """One tick: the observation after it and, on a chunk's 4th tick, the env step it sent
    (a TensorDict with ``"action"`` ``[N, 4, 2]`` and ``"next"``; None on the other ticks)."""

    observation: FrameObservation
    chunk: TensorDictBase | None


class FrameStepper:
    """Steps a batched world-model env (:class:`~oasis_torchrl.envs.OasisEnv` or the env
    factory's) one action per frame, by sample and hold (see the module docs).

    Args:
        env: a TorchRL env taking ``[N, 4, 2]`` chunks and returning ``("pixels", camera)``
            frames (the chunk's last, or all 4) and ``"state"``.

    Example:
        >>> from oasis_torchrl.config import EnvConfig
        >>> from oasis_torchrl.envs import make_env
        >>> stepper = FrameStepper(make_env(EnvConfig(num_envs=2)))
        >>> first = stepper.reset(seed=3)
        >>> ticks = [stepper.step(np.full((2, 2), 0.5, np.float32)) for _ in range(4)]
        >>> [tick.chunk is not None for tick in ticks], ticks[0].observation.state[0].tolist()
        ([False, False, False, True], [0.5, 0.5])
        >>> bool((ticks[2].observation.pixels["front"] == first.pixels["front"]).all())
        True
        >>> stepper.close()
    """

    def __init__(self, env: EnvBase) -> None:
        self.env = env
        self.num_envs = int(env.batch_size[0])
        self._actions: list[torch.Tensor] = []
        self._last: TensorDictBase | None = None
        self._observation: FrameObservation | None = None

    @property
    def tick(self) -> int:
        """Actions buffered in the current chunk (0 to 3)."""
        return len(self._actions)

    @property
    def last(self) -> TensorDictBase:
        """The newest chunk-level observation (frames, state, ground truth, ...)."""
        if self._last is None:
            raise RuntimeError("reset the stepper first")
        return self._last

    @property
    def observation(self) -> FrameObservation:
        """What the rows see now."""
        if self._observation is None:
            raise RuntimeError("reset the stepper first")
        return self._observation

    def reset(self, seed: int | None = None) -> FrameObservation:
        """Start every row's next episode (seeded from ``seed``, as ``env.set_seed``); buffered
        actions are dropped."""
        if seed is not None:
            self.env.set_seed(int(seed))
        self._actions.clear()
        self._hold(self.env.reset())
        return self.observation

    def step(self, action: np.ndarray | torch.Tensor) -> FrameStep:
        """Apply one ``[N, 2]`` action per row (clipped to ``[-1, 1]``).

        Raises:
            ValueError: a wrong shape, or a row's action is not finite.
        """
        if self._observation is None:
            raise RuntimeError("reset the stepper before stepping it")
        action = torch.as_tensor(np.asarray(action, dtype=np.float32))
        if tuple(action.shape) != (self.num_envs, ACTION_DIM):
            raise ValueError(
                f"one [throttle, steering] per row expected: shape ({self.num_envs}, "
                f"{ACTION_DIM}), got {tuple(action.shape)}"
            )
        bad = (~torch.isfinite(action)).any(-1)
        if bad.any():
            raise ValueError(f"the action of row {int(bad.nonzero()[0])} is not finite")
        action = action.clamp(-1.0, 1.0)
        self._actions.append(action)
        chunk = None
        if len(self._actions) == CHUNK:
            actions = torch.stack(self._actions, dim=1)
            chunk = self.env.step(self.last.clone(False).set("action", actions))
            self._actions.clear()
            self._hold(step_mdp(chunk))
        self._observation = FrameObservation(self._observation.pixels, action.numpy())
        return FrameStep(self._observation, chunk)

    def close(self) -> None:
        """Close the env (its sessions and, for a local endpoint, its server)."""
        if not self.env.is_closed:
            self.env.close()

    def _hold(self, td: TensorDictBase) -> None:
        """Hold ``td``'s newest frames; the state is its previous action."""
        self._last = td
        pixels = {}
        for camera, frames in td.get("pixels").items():
            newest = frames[:, -1] if frames.dim() == 5 else frames
            pixels[camera] = np.ascontiguousarray(newest.cpu().numpy())
        state = td.get("state").to("cpu", torch.float32).numpy()
        self._observation = FrameObservation(pixels, state)
