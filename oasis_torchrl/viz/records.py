"""What one env step (or reset) of the logged rows holds, read from the env's TensorDicts.

Keys follow :mod:`oasis_torchrl.envs.specs`; everything but the camera frames is optional, so
transformed envs and remote endpoints (no ground truth, no depth) log what they have. Arrays are
copies (indexing with the row list copies), so a background writer never sees a buffer that a
collector overwrites in place.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from tensordict import TensorDictBase

from oasis_torchrl.protocol import CHUNK, FRONT_CROP

PIXELS, DEPTH, TRUTH, TERMS = "pixels", "depth", "truth", "reward_terms"


@dataclass
class StepRecord:
    """One reset (``start``) or step of the logged ``rows`` (``R`` of them), as numpy arrays.

    ``images[camera]``: uint8 ``[R, F, H, W, 3]`` (``F`` = 1, the last frame, or 4);
    ``depth[camera]``: float32 ``[R, H, W]``; ``actions``: float32 ``[R, 4, 2]``; ``reward``,
    ``terms[name]``: ``[R]``; ``truth[field]``: ``[R, 4]``; ``terminated``/``truncated``/``done``:
    bool ``[R]``; ``prompts``/``seeds``: per row, for episode starts; ``episodes``: per row, the
    numbers of the episodes a start begins when the caller names them.

    Example:
        >>> record = StepRecord(rows=[0], start=True)
        >>> record.actions is None, record.images
        (True, {})
    """

    rows: list[int]
    start: bool
    images: dict[str, np.ndarray] = field(default_factory=dict)
    depth: dict[str, np.ndarray] = field(default_factory=dict)
    actions: np.ndarray | None = None
    reward: np.ndarray | None = None
    terms: dict[str, np.ndarray] = field(default_factory=dict)
    truth: dict[str, np.ndarray] = field(default_factory=dict)
    terminated: np.ndarray | None = None
    truncated: np.ndarray | None = None
    done: np.ndarray | None = None
    prompts: list[str] | None = None
    seeds: list[int] | None = None
    episodes: list[int] | None = None


def batch_rows(td: TensorDictBase) -> int:
    """Number of env rows of a one-step TensorDict (batch ``[N]``).

    Example:
        >>> from tensordict import TensorDict
        >>> batch_rows(TensorDict(batch_size=[3]))
        3
    """
    if td.batch_dims != 1:
        raise ValueError(
            f"expected one step of a batched env (batch size [N]), got batch size "
            f"{list(td.batch_size)}"
        )
    return int(td.batch_size[0])


def _numpy(value: torch.Tensor, index: np.ndarray) -> np.ndarray:
    # numpy's fancy indexing copies rows at memcpy speed; torch's uint8 gather is far slower.
    return value.detach().cpu().numpy()[index]


def _group(td: TensorDictBase, group: str, index: np.ndarray) -> dict[str, np.ndarray]:
    sub = td.get(group, None)
    if sub is None:
        return {}
    return {name: _numpy(sub.get(name), index) for name in sub.keys(leaves_only=True)}


def _wanted(camera: str, cameras: Sequence[str] | None) -> bool:
    """Whether to read ``camera``: one of ``cameras``, or by default any but the front crop."""
    return camera != FRONT_CROP if cameras is None else camera in cameras


def _frames(
    td: TensorDictBase, index: np.ndarray, cameras: Sequence[str] | None
) -> dict[str, np.ndarray]:
    pixels = td.get(PIXELS, None)
    if pixels is None:
        return {}
    out = {}
    for camera in pixels.keys(leaves_only=True):
        if not _wanted(camera, cameras):
            continue
        frames = pixels.get(camera)
        if frames.dtype != torch.uint8 or frames.shape[-1] != 3 or frames.ndim not in (4, 5):
            raise TypeError(
                f"('pixels', {camera!r}) must be uint8 [N, H, W, 3] or [N, 4, H, W, 3] (HWC), "
                f"got {frames.dtype} {list(frames.shape)}"
            )
        array = _numpy(frames, index)
        out[camera] = array[:, None] if array.ndim == 4 else array
    return out


def _actions(action: torch.Tensor, index: np.ndarray) -> np.ndarray:
    """``[R, 4, 2]`` from a chunk ``[N, 4, 2]`` or a single action ``[N, 2]`` (repeated)."""
    array = _numpy(action, index).astype(np.float32, copy=False)
    if array.shape[1:] == (2,):
        return np.repeat(array[:, None], CHUNK, axis=1)
    if array.shape[1:] != (CHUNK, 2):
        raise ValueError(
            f"action must be [N, {CHUNK}, 2] or [N, 2] ([throttle, steering]), got "
            f"{list(action.shape)}"
        )
    return array


def _flag(td: TensorDictBase, key: str, index: np.ndarray) -> np.ndarray | None:
    value = td.get(key, None)
    return None if value is None else _numpy(value, index).reshape(len(index)).astype(bool)


def _strings(td: TensorDictBase, key: str, rows: Sequence[int]) -> list[str] | None:
    value = td.get(key, None)
    if value is None:
        return None
    data = value.tolist() if hasattr(value, "tolist") else value
    if isinstance(data, str):
        return [data] * len(rows)
    return [str(data[row]) for row in rows]


def read_step(
    td: TensorDictBase,
    rows: Sequence[int],
    *,
    start: bool,
    action: torch.Tensor | None = None,
    cameras: Sequence[str] | None = None,
    depth: bool = True,
) -> StepRecord:
    """The record of ``rows`` in a one-step observation ``td`` (batch ``[N]``).

    Args:
        td: a reset output, or the ``"next"`` observation of a step (with reward and flags).
        rows: env rows to read.
        start: ``td`` is a reset observation (the rows start new episodes).
        action: the action ``[N, 4, 2]`` or ``[N, 2]`` that led to ``td``.
        cameras: cameras to read (default: all under ``"pixels"`` but the front crop, a part
            of the front camera's frame).
        depth: read ``("depth", camera)`` maps.

    Example:
        >>> from tensordict import TensorDict
        >>> td = TensorDict({("pixels", "front"): torch.zeros(2, 4, 6, 3, dtype=torch.uint8),
        ...                  "reward": torch.ones(2, 1)}, [2])
        >>> record = read_step(td, [1], start=False, action=torch.zeros(2, 2))
        >>> record.images["front"].shape, record.actions.shape, record.reward.tolist()
        ((1, 1, 4, 6, 3), (1, 4, 2), [1.0])
    """
    n = batch_rows(td)
    bad = [row for row in rows if not 0 <= row < n]
    if bad:
        raise ValueError(f"env rows {bad} are outside the batch of {n} rows")
    index = np.asarray(rows, dtype=np.int64)
    reward = td.get("reward", None)
    seeds = td.get("episode_seed", None)
    return StepRecord(
        rows=list(rows),
        start=start,
        images=_frames(td, index, cameras),
        depth=_group(td, DEPTH, index) if depth else {},
        actions=None if action is None else _actions(action, index),
        reward=None if reward is None else _numpy(reward, index).reshape(len(rows)),
        terms={k: v.reshape(len(rows)) for k, v in _group(td, TERMS, index).items()},
        truth=_group(td, TRUTH, index),
        terminated=_flag(td, "terminated", index),
        truncated=_flag(td, "truncated", index),
        done=_flag(td, "done", index),
        prompts=_strings(td, "prompt", rows),
        seeds=None if seeds is None else _numpy(seeds, index).reshape(len(rows)).tolist(),
    )


def read_frames(frames: Mapping[str, Sequence[np.ndarray]], row: int, start: bool) -> StepRecord:
    """The record of one client chunk (``FrameConsumer.submit``): frames only.

    Example:
        >>> chunk = {"front": [np.zeros((4, 6, 3), np.uint8)] * 4}
        >>> read_frames(chunk, row=0, start=True).images["front"].shape
        (1, 4, 4, 6, 3)
    """
    return StepRecord(
        rows=[row],
        start=start,
        images={camera: np.stack(list(chunk))[None] for camera, chunk in frames.items()},
    )
