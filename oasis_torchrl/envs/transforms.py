"""TorchRL transforms of the Oasis env: the frame stack a policy reads, and the privileged
state an asymmetric critic reads."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import Bounded, Composite, Unbounded
from torchrl.envs import Transform

from oasis_torchrl.models.actor_critic import CRITIC_INPUTS, FRAME_STACK, PIXELS
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, privileged_state


class ChunkFrameStack(Transform):
    """Writes ``(FRAME_STACK, <camera>)`` uint8 ``[N, depth, H, W, 3]``: the last frame of each
    of the last ``depth`` chunks, oldest first, so frames one chunk (4 world frames) apart.

    It reads the env's ``("pixels", <camera>)`` (all 4 frames of a chunk or the last one) and,
    on a step, the stack of the observation being stepped from: no state is kept, so the env
    pickles, and the stack moves with the tensordict. A reset row's stack is its reset frame
    repeated (LeRobot fills a policy's first history the same way); rows a partial reset leaves
    running keep theirs.

    Why one chunk apart and not consecutive frames: LeRobot's per-frame loops
    (:mod:`oasis_torchrl.envs.per_frame`) cannot show a frame before the world has its chunk's 4
    actions, so at every chunk boundary the two newest frames a policy has seen there are the
    last frames of the two previous chunks. Training on the same spacing everywhere makes a
    policy act the same under ``lerobot-eval`` and ``oasis-torchrl eval``.

    Example:
        >>> from tensordict import TensorDict
        >>> def chunk(first: int) -> TensorDict:  # 2 rows, 4 frames of 2x2 pixels
        ...     frames = torch.arange(first, first + 8).reshape(2, 4, 1, 1, 1)
        ...     return TensorDict({"pixels": {"front": frames.expand(2, 4, 2, 2, 3).byte()}}, [2])
        >>> stack = ChunkFrameStack(["front"], depth=2)
        >>> first = stack._reset(TensorDict(), chunk(0))
        >>> first["frame_stack", "front"][:, :, 0, 0, 0].tolist()
        [[3, 3], [7, 7]]
        >>> after = stack._step(first, chunk(10))
        >>> after["frame_stack", "front"][:, :, 0, 0, 0].tolist()
        [[3, 13], [7, 17]]
    """

    def __init__(self, cameras: list[str] | tuple[str, ...], depth: int = 2) -> None:
        if depth < 1:
            raise ValueError(f"ChunkFrameStack depth must be >= 1, got {depth}")
        super().__init__(
            in_keys=[(PIXELS, camera) for camera in cameras],
            out_keys=[(FRAME_STACK, camera) for camera in cameras],
        )
        self.depth = depth

    def _repeated(self, newest: torch.Tensor) -> torch.Tensor:
        """A stack of ``newest`` (``[*B, 1, H, W, 3]``) alone: a fresh episode's."""
        return newest.expand(*newest.shape[:-4], self.depth, *newest.shape[-3:])

    @staticmethod
    def _newest(frames: torch.Tensor, batch_dims: int) -> torch.Tensor:
        """The chunk's last frame ``[*B, 1, H, W, 3]`` of ``[*B, (4,) H, W, 3]`` frames."""
        if frames.dim() == batch_dims + 4:
            return frames[..., -1:, :, :, :]
        return frames.unsqueeze(-4)

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        batch_dims = next_tensordict.batch_dims
        for in_key, out_key in zip(self.in_keys, self.out_keys, strict=True):
            newest = self._newest(next_tensordict.get(in_key), batch_dims)
            previous = tensordict.get(out_key, None)
            if previous is None:  # stepped from an observation without a stack: start one
                stack = self._repeated(newest)
            else:
                stack = torch.cat([previous[..., 1:, :, :, :], newest], dim=-4)
            next_tensordict.set(out_key, stack.contiguous())
        return next_tensordict

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        batch_dims = tensordict_reset.batch_dims
        reset = None if tensordict is None else tensordict.get("_reset", None)
        for in_key, out_key in zip(self.in_keys, self.out_keys, strict=True):
            newest = self._newest(tensordict_reset.get(in_key), batch_dims)
            stack = self._repeated(newest).contiguous()
            previous = None if reset is None else tensordict.get(out_key, None)
            if previous is not None and previous.shape == stack.shape:
                running = ~reset.reshape(*stack.shape[:batch_dims])
                stack[running] = previous[running]
            tensordict_reset.set(out_key, stack)
        return tensordict_reset

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        for in_key, out_key in zip(self.in_keys, self.out_keys, strict=True):
            frames = observation_spec[in_key]
            frame = frames.shape[-3:]
            batch = frames.shape[: len(observation_spec.shape)]
            observation_spec[out_key] = Bounded(
                0, 255, (*batch, self.depth, *frame), dtype=torch.uint8, device=frames.device
            )
        return observation_spec


class PrivilegedState(Transform):
    """Writes ``"critic_inputs"`` ``[N, len(PRIVILEGED_FIELDS)]``: the last frame's ground truth in
    :data:`~oasis_torchrl.models.privileged.PRIVILEGED_FIELDS` (speed, offsets on the road
    and in the lane, the lanes beside, obstacle distances ahead in the car's path, its lane and
    the lanes left and right), scaled to about unit size
    (:func:`~oasis_torchrl.models.privileged.privileged_state`).

    For an asymmetric actor-critic on the embedded server: the critic may use the simulator's
    state, the actor (what is deployed) only sees the cameras and the previous action.

    Example:
        >>> from tensordict import TensorDict
        >>> truth = {field: torch.full((2, 4), 2.0) for field in PRIVILEGED_FIELDS}
        >>> truth["lane_obstacle_distance_right"][0] = float("inf")
        >>> out = PrivilegedState()(TensorDict({"truth": truth}, [2]))
        >>> out["critic_inputs"][:, -1].tolist()
        [1.0, 0.03333333507180214]
    """

    def __init__(self) -> None:
        in_keys = [("truth", field) for field in PRIVILEGED_FIELDS]
        super().__init__(in_keys=in_keys, out_keys=[CRITIC_INPUTS])

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        last = {key[-1]: next_tensordict.get(key)[..., -1] for key in self.in_keys}
        return next_tensordict.set(CRITIC_INPUTS, privileged_state(last))

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Add ``"critic_inputs"`` to a TensorDict outside an env (e.g. a stored batch)."""
        return self._call(tensordict)

    def _reset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        shape = (*observation_spec.shape, len(PRIVILEGED_FIELDS))
        observation_spec[CRITIC_INPUTS] = Unbounded(shape, device=observation_spec.device)
        return observation_spec
