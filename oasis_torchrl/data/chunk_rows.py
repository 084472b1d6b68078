"""How TorchRL env steps become LeRobot dataset rows (the chunk-to-row mapping).

One env step ``t`` of one env row holds the root observation ``O_t`` (the frames of the
previous chunk, or of the reset chunk: the env resets by standing still for one chunk), the
action chunk ``A_t = (a0, a1, a2, a3)``, the next observation ``O_t+1`` whose frames
``f0..f3`` are the world after ``a0..a3``, the chunk reward ``r_t`` and the done flag ``d_t``.
``state`` is the env's ``"state"`` key: the action applied before the observation.

**Frame rows** (``OasisEnv(all_frames=True)``: pixels ``[..., 4, H, W, 3]``), dataset fps =
world fps (20): four rows per step.

=========  ==================  =================  ==========  ==============  =============
row        image               observation.state  action      next.reward     next.done
=========  ==================  =================  ==========  ==============  =============
``4t``     last frame of O_t   ``state`` of O_t   ``a0``      0               False
``4t+1``   ``f0``              ``a0``             ``a1``      0               False
``4t+2``   ``f1``              ``a1``             ``a2``      0               False
``4t+3``   ``f2``              ``a2``             ``a3``      ``r_t``         ``d_t``
=========  ==================  =================  ==========  ==============  =============

**Chunk rows** (default env: pixels ``[..., H, W, 3]``, the last frame of each chunk),
dataset fps = world fps / 4 (5): one row per step, image = last frame of ``O_t``, state =
``state`` of ``O_t``, action = the chunk flattened ``[t0, s0, ..., t3, s3]`` (or the single
``[throttle, steering]`` of an env with ``chunk_actions=False``), reward ``r_t``, done ``d_t``.

A batch with an ``"intervention"`` key (bool ``[..., T, 1]``: a person drove the step over a
policy) adds the ``intervention`` column, the step's flag on each of its rows; one with a
``("next", "crash")`` key (bool ``[..., T, 1]``: the car crashed during the step) adds the
``next.crash`` column, the step's flag on its last row (as ``next.done``).

So the chunk reward sits on the row whose action completes the chunk (sums over an episode are
preserved), every row's action is the one applied next, and the reset observation is row 0 of
each episode. The observation after the last step has no next action and is not stored: an
episode of ``T`` steps has ``4T`` (or ``T``) rows.

Batches are ``[..., T]`` TensorDicts (``env.rollout`` output or collector batches; time is the
last batch dimension, leading dimensions are env rows).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from lerobot.utils.constants import ACTION, DONE, OBS_STATE, REWARD
from tensordict import NonTensorData, TensorDictBase

from oasis_torchrl.data.features import (
    CRASH_KEY,
    INTERVENTION_KEY,
    SEED_KEY,
    DatasetLayout,
    image_key,
)
from oasis_torchrl.data.images import resize_frames
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, PRIVILEGED_KEY, privileged_state
from oasis_torchrl.protocol import CAMERAS, CHUNK

PIXELS = "pixels"
NEXT = "next"
CRASH_STEP_KEY = "crash"
"""The step key (under ``"next"``) of a crash mark."""
TRUTH = "truth"


@dataclass(frozen=True)
class RowBatch:
    """Dataset rows of a ``[B, T]`` batch of env steps, ``R`` rows per step.

    ``columns`` maps each dataset key to a numpy array ``[B, T, R, *feature_shape]``;
    ``tasks`` is ``[B][T]`` prompts, ``seeds`` int64 ``[B, T]`` and ``done`` bool ``[B, T]``.

    Example:
        >>> rows = RowBatch({"action": np.zeros((1, 2, 4, 2), np.float32)}, [["city"] * 2],
        ...                 np.zeros((1, 2), np.int64), np.array([[False, True]]))
        >>> rows.shape, rows.step(0, 1)["action"].shape
        ((1, 2), (4, 2))
    """

    columns: dict[str, np.ndarray]
    tasks: list[list[str]]
    seeds: np.ndarray
    done: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """``(B, T)``: env rows and steps."""
        return self.done.shape

    def step(self, row: int, step: int) -> dict[str, np.ndarray]:
        """The ``R`` dataset rows of one env row's step, ``key -> [R, ...]``."""
        return {key: values[row, step] for key, values in self.columns.items()}


def _get(batch: TensorDictBase, key: str | tuple[str, ...], purpose: str) -> torch.Tensor:
    value = batch.get(key, None)
    if value is None:
        raise KeyError(f"the batch has no {key!r} ({purpose})")
    return value


def _as_steps(batch: TensorDictBase) -> TensorDictBase:
    """View ``batch`` as ``[B, T]``: time last, every leading dimension an env row."""
    if batch.batch_dims == 0:
        raise ValueError("a batch needs a time dimension, got batch_size []")
    if batch.batch_dims == 1:
        return batch.unsqueeze(0)
    if batch.batch_dims == 2:
        return batch
    return batch.reshape(-1, batch.batch_size[-1])


def _cameras(batch: TensorDictBase) -> tuple[str, ...]:
    """Camera names in the conventional order (TensorDict ops may reorder keys)."""
    names = [str(key) for key in _get(batch, PIXELS, "the camera frames").keys()]
    known = [camera for camera in CAMERAS if camera in names]
    return (*known, *sorted(set(names) - set(known)))


def infer_layout(
    batch: TensorDictBase, image_size: tuple[int, int] | None = None, privileged: bool = False
) -> DatasetLayout:
    """The dataset layout a batch calls for: cameras, frame size, rows per step.

    Args:
        batch: env steps ``[..., T]`` as :mod:`oasis_torchrl.envs.specs` lays them out.
        image_size: stored ``(height, width)``; default: the frames' own size.
        privileged: store each frame's ``privileged_state`` (from the batch's ground truth).

    Example:
        >>> from tensordict import TensorDict
        >>> steps = TensorDict({"pixels": {"front": torch.zeros(2, 3, 4, 48, 64, 3,
        ...     dtype=torch.uint8)}, "action": torch.zeros(2, 3, 4, 2)}, batch_size=[2, 3])
        >>> infer_layout(steps).actions_per_row  # all 4 frames: one action per row
        1
    """
    steps = _as_steps(batch)
    cameras = _cameras(steps)
    pixels = _get(steps, (PIXELS, cameras[0]), "the camera frames")
    action = _get(steps, ACTION, "the applied action")
    frame_rows = pixels.dim() == 6
    chunked = action.dim() == 4
    actions_per_row = 1 if frame_rows or not chunked else action.shape[-2]
    size = image_size or tuple(pixels.shape[-3:-1])
    return DatasetLayout(
        cameras,
        size,
        actions_per_row=actions_per_row,
        with_privileged=privileged,
        with_intervention=INTERVENTION_KEY in steps.keys(),
        with_crash=(NEXT, CRASH_STEP_KEY) in steps.keys(include_nested=True),
    )


def rows_per_step(batch: TensorDictBase) -> int:
    """4 for frame rows (pixels ``[..., 4, H, W, 3]``), 1 for chunk rows.

    Example:
        >>> from tensordict import TensorDict
        >>> steps = TensorDict({"pixels": {"front": torch.zeros(2, 3, 48, 64, 3,
        ...     dtype=torch.uint8)}}, batch_size=[2, 3])
        >>> rows_per_step(steps), frame_size(steps)
        (1, (48, 64))
    """
    steps = _as_steps(batch)
    pixels = _get(steps, (PIXELS, _cameras(steps)[0]), "the camera frames")
    return pixels.shape[2] if pixels.dim() == 6 else 1


def _frames(
    steps: TensorDictBase, camera: str, size: tuple[int, int], source: tuple[int, int] | None
) -> torch.Tensor:
    """``[B, T, R, H, W, 3]`` uint8: the image of each row (see the mapping table)."""
    root = _get(steps, (PIXELS, camera), "the frames before each action")
    if root.dtype != torch.uint8:
        raise TypeError(f"('pixels', {camera!r}) must be uint8, got {root.dtype}")
    if source is not None and tuple(root.shape[-3:-1]) != tuple(source):
        raise ValueError(
            f"('pixels', {camera!r}): expected {source[0]}x{source[1]} frames (height x width) "
            f"as in earlier batches, got shape {tuple(root.shape)}"
        )
    if root.dim() == 5:
        images = root.unsqueeze(2)
    elif root.dim() == 6:
        after = _get(steps, (NEXT, PIXELS, camera), "the frames after each action")
        images = _frame_rows(root, after)
    else:
        raise ValueError(
            f"('pixels', {camera!r}) must be [B, T, H, W, 3] or [B, T, 4, H, W, 3], "
            f"got {tuple(root.shape)}"
        )
    return resize_frames(images.cpu(), size)


def _frame_rows(root: torch.Tensor, after: torch.Tensor) -> torch.Tensor:
    """Per-frame values ``[B, T, 4, ...]`` of each frame row (the table): the root observation's
    last frame, then the chunk's frames before its last."""
    return torch.cat([root[:, :, -1:], after[:, :, :-1]], dim=2)


def _privileged(steps: TensorDictBase, rows: int) -> torch.Tensor:
    """``[B, T, R, len(PRIVILEGED_FIELDS)]``: the privileged state of each row's frame (see
    the mapping table)."""
    truth = {}
    for field in PRIVILEGED_FIELDS:
        root = _get(steps, (TRUTH, field), "the ground truth of the privileged state")
        if rows > 1:
            after = _get(steps, (NEXT, TRUTH, field), "the ground truth after each action")
            truth[field] = _frame_rows(root, after)
        else:
            truth[field] = root[:, :, -1:]
    return privileged_state({field: value.cpu() for field, value in truth.items()})


def _actions(steps: TensorDictBase, rows: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(state, action)`` per row, ``[B, T, R, 2]`` and ``[B, T, R, A]``."""
    action = _get(steps, ACTION, "the applied action").detach().cpu().float()
    previous = _get(steps, "state", "the action applied before each frame").cpu().float()
    batch = tuple(steps.batch_size)
    if previous.shape != (*batch, 2):
        raise ValueError(f"'state' must be {[*batch, 2]}, got {list(previous.shape)}")
    if action.shape not in ((*batch, 2), (*batch, CHUNK, 2)):
        raise ValueError(
            f"'action' must be {[*batch, CHUNK, 2]} or {[*batch, 2]}, got {list(action.shape)}"
        )
    if rows == 1:
        return previous.unsqueeze(2), action.reshape(*batch, 1, -1)
    if action.dim() == 3:  # one action repeated over the chunk
        action = action.unsqueeze(2).expand(*batch, CHUNK, 2)
    if action.shape[2] != rows:
        raise ValueError(f"{rows} frames per step but {action.shape[2]} actions per chunk")
    state = torch.cat([previous.unsqueeze(2), action[:, :, :-1]], dim=2)
    return state, action


def _on_last_row(values: torch.Tensor, rows: int) -> torch.Tensor:
    """``[B, T, 1]`` per-step values -> ``[B, T, R, 1]``: on the last row, zero elsewhere."""
    out = torch.zeros(*values.shape[:2], rows, 1, dtype=values.dtype)
    out[:, :, -1] = values
    return out


def _tasks(steps: TensorDictBase) -> list[list[str]]:
    batch, horizon = steps.batch_size
    value = steps.get("prompt", None)
    if value is None:
        raise KeyError("the batch has no 'prompt' (the task of each episode)")
    if isinstance(value, NonTensorData):
        value = value.data
    if isinstance(value, str):
        return [[value] * horizon for _ in range(batch)]
    tasks = value.tolist()
    if len(tasks) != batch or any(len(row) != horizon for row in tasks):
        raise ValueError(f"'prompt' must hold one string per step [{batch}, {horizon}]")
    return tasks


def frame_size(batch: TensorDictBase) -> tuple[int, int]:
    """``(height, width)`` of the batch's frames (before any resizing); see
    :func:`rows_per_step` for an example."""
    steps = _as_steps(batch)
    pixels = _get(steps, (PIXELS, _cameras(steps)[0]), "the camera frames")
    return tuple(pixels.shape[-3:-1])


def batch_to_rows(
    batch: TensorDictBase, layout: DatasetLayout, source_size: tuple[int, int] | None = None
) -> RowBatch:
    """Map a batch of env steps to dataset rows (see the module docstring for the mapping).

    Frames are resized to ``layout.image_size``; ``source_size``, if given, is the frame size
    the batch must have (a recorder's later batches must match its first).

    Example:
        >>> from tensordict import TensorDict
        >>> n, t = 1, 2
        >>> steps = TensorDict({
        ...     "pixels": {"front": torch.zeros(n, t, 48, 64, 3, dtype=torch.uint8)},
        ...     "state": torch.zeros(n, t, 2), "action": torch.ones(n, t, 4, 2),
        ...     "prompt": "rural road", "episode_seed": torch.zeros(n, t, 1, dtype=torch.int64),
        ...     "next": {"reward": torch.ones(n, t, 1),
        ...              "done": torch.tensor([[[False], [True]]])},
        ... }, batch_size=[n, t])
        >>> rows = batch_to_rows(steps, infer_layout(steps))
        >>> rows.columns["action"].shape, rows.done.tolist()
        ((1, 2, 1, 8), [[False, True]])
    """
    steps = _as_steps(batch)
    rows = rows_per_step(steps)
    columns = {
        image_key(camera): _frames(steps, camera, layout.image_size, source_size).numpy()
        for camera in layout.cameras
    }
    state, action = _actions(steps, rows)
    columns[OBS_STATE] = state.numpy()
    columns[ACTION] = action.contiguous().numpy()
    done = _get(steps, (NEXT, "done"), "the episode ends").cpu().reshape(*steps.batch_size, 1)
    if layout.with_reward:
        reward = _get(steps, (NEXT, "reward"), "the chunk reward").detach().cpu().float()
        columns[REWARD] = _on_last_row(reward.reshape(*steps.batch_size, 1), rows).numpy()
    columns[DONE] = _on_last_row(done.bool(), rows).numpy()
    if layout.with_crash:
        crashed = _get(steps, (NEXT, CRASH_STEP_KEY), "the crash marks").cpu().bool()
        columns[CRASH_KEY] = _on_last_row(crashed.reshape(*steps.batch_size, 1), rows).numpy()
    if layout.with_privileged:
        columns[PRIVILEGED_KEY] = _privileged(steps, rows).numpy()
    if layout.with_intervention:
        flags = _get(steps, INTERVENTION_KEY, "who drove each step").cpu().bool()
        columns[INTERVENTION_KEY] = (
            flags.reshape(*steps.batch_size, 1, 1).expand(-1, -1, rows, 1).numpy()
        )
    seeds = _get(steps, SEED_KEY, "the world seed of each episode").cpu().reshape(*steps.batch_size)
    if layout.with_seed:
        columns[SEED_KEY] = seeds.reshape(*steps.batch_size, 1, 1).expand(-1, -1, rows, 1).numpy()
    return RowBatch(columns, _tasks(steps), seeds.numpy(), done.squeeze(-1).numpy())
