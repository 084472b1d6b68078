"""TorchRL specs of :class:`~oasis_torchrl.envs.OasisEnv`.

TensorDict layout of one env (batch size ``[N]``, one row per world-model session):

============================  =========================  =======================================
key                           dtype / shape              meaning
============================  =========================  =======================================
``("pixels", <camera>)``      uint8 ``[N, H, W, 3]``     last frame of the chunk (HWC, as TorchRL
                                                         pixel transforms expect); with
                                                         ``all_frames=True`` ``[N, 4, H, W, 3]``
``"state"``                   float32 ``[N, 2]``         the previous action ``[throttle,
                                                         steering]`` (zeros after a reset)
``"prompt"``                  str ``[N]`` (non-tensor)   the prompt of the row's episode
``"episode_seed"``            int64 ``[N, 1]``           the seed of the row's episode
``("truth", <field>)``        float32 ``[N, 4]``         embedded-server ground truth per frame
                                                         of the chunk (see ``TRUTH_FIELDS``)
``"expert_action"``           float32 ``[N, 4, 2]``      with ``expert=True``: the embedded
                                                         server's expert's next chunk from the
                                                         row's state (NaN where none was sent)
``("depth", <camera>)``       float32 ``[N, H, W]``      metric depth of the last frame (opt-in)
``("reward_terms", <term>)``  float32 ``[N, 1]``         every term of the reward, for logging
``("info", "session_restarts")`` int64 ``[N, 1]``        sessions this row lost and re-opened
``"action"``                  float32 ``[N, 4, 2]``      a chunk of 4 ``[throttle, steering]``;
                                                         ``[N, 2]`` with ``chunk_actions=False``
``"reward"``                  float32 ``[N, 1]``
``"done"/"terminated"/"truncated"`` bool ``[N, 1]``
============================  =========================  =======================================
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
from torchrl.data import Bounded, Categorical, Composite, NonTensor, Unbounded

from oasis_torchrl.protocol import ACTION_DIM, CAMERAS, CHUNK, HOSTED_FRAME_SIZE

if TYPE_CHECKING:
    from oasis_torchrl.client import SessionPool

"""Actions per Infer call and frames per stream in every response."""


@dataclass(frozen=True)
class StreamLayout:
    """The cameras an env returns and the ``(height, width)`` of their frames.

    Example:
        >>> StreamLayout.hosted().frame_size
        (512, 768)
    """

    cameras: tuple[str, ...]
    frame_size: tuple[int, int]

    @classmethod
    def hosted(cls) -> StreamLayout:
        """What the hosted Oasis model advertises."""
        return cls(CAMERAS, HOSTED_FRAME_SIZE)

    def check(self, pool: SessionPool) -> None:
        """Raise if a started pool streams something else (naming both and the fix)."""
        served = StreamLayout(tuple(pool.stream_names), tuple(pool.frame_size))
        if served != self:
            raise ValueError(
                f"the server streams {served.cameras} at {served.frame_size}, the env was built "
                f"for {self.cameras} at {self.frame_size}: pass frame_size=(height, width) to "
                "decode to a size of your choice, or streams=StreamLayout(...) with the server's"
            )


@dataclass(frozen=True)
class EnvLayout:
    """Everything the specs depend on.

    Example:
        >>> layout = EnvLayout(num_envs=2, cameras=("front",), frame_size=(64, 96))
        >>> build_observation_spec(layout)["pixels", "front"].shape
        torch.Size([2, 64, 96, 3])
    """

    num_envs: int
    cameras: tuple[str, ...]
    frame_size: tuple[int, int]
    all_frames: bool = False
    chunk_actions: bool = True
    truth_fields: tuple[str, ...] = ()
    expert: bool = False
    depth_cameras: tuple[str, ...] = ()
    reward_terms: tuple[str, ...] = ()
    device: torch.device | str = "cpu"

    @property
    def batch(self) -> torch.Size:
        return torch.Size([self.num_envs])


def _pixels_shape(layout: EnvLayout) -> tuple[int, ...]:
    height, width = layout.frame_size
    frames = (CHUNK,) if layout.all_frames else ()
    return (layout.num_envs, *frames, height, width, 3)


def _group(layout: EnvLayout, names: Sequence[str], spec_for) -> Composite:
    return Composite({name: spec_for() for name in names}, shape=layout.batch, device=layout.device)


def build_observation_spec(layout: EnvLayout) -> Composite:
    """Observation spec: pixels per camera, previous action, optional truth/depth/terms."""
    n, device = layout.num_envs, layout.device
    spec = Composite(shape=layout.batch, device=device)
    spec["pixels"] = _group(
        layout,
        layout.cameras,
        lambda: Bounded(0, 255, _pixels_shape(layout), dtype=torch.uint8, device=device),
    )
    spec["state"] = Bounded(-1.0, 1.0, (n, 2), dtype=torch.float32, device=device)
    spec["prompt"] = NonTensor(shape=(n,), example_data="urban street", device=device)
    spec["episode_seed"] = Unbounded((n, 1), dtype=torch.int64, device=device)
    if layout.truth_fields:
        spec["truth"] = _group(
            layout, layout.truth_fields, lambda: Unbounded((n, CHUNK), device=device)
        )
    if layout.expert:
        spec["expert_action"] = Unbounded((n, CHUNK, ACTION_DIM), device=device)
    if layout.depth_cameras:
        height, width = layout.frame_size
        spec["depth"] = _group(
            layout,
            layout.depth_cameras,
            lambda: Unbounded((n, height, width), device=device),
        )
    if layout.reward_terms:
        spec["reward_terms"] = _group(
            layout, layout.reward_terms, lambda: Unbounded((n, 1), device=device)
        )
    spec["info"] = Composite(
        session_restarts=Unbounded((n, 1), dtype=torch.int64, device=device),
        shape=layout.batch,
        device=device,
    )
    return spec


def build_action_spec(layout: EnvLayout) -> Bounded:
    """Actions in ``[-1, 1]``: a chunk ``[N, 4, 2]`` or one action ``[N, 2]`` repeated."""
    shape = (layout.num_envs, CHUNK, 2) if layout.chunk_actions else (layout.num_envs, 2)
    return Bounded(-1.0, 1.0, shape, dtype=torch.float32, device=layout.device)


def build_reward_spec(layout: EnvLayout) -> Unbounded:
    """One scalar reward per row."""
    return Unbounded((layout.num_envs, 1), dtype=torch.float32, device=layout.device)


def build_done_spec(layout: EnvLayout) -> Composite:
    """``done``, ``terminated`` and ``truncated`` flags per row."""
    flag = lambda: Categorical(  # noqa: E731
        2, (layout.num_envs, 1), dtype=torch.bool, device=layout.device
    )
    return Composite(
        done=flag(), terminated=flag(), truncated=flag(), shape=layout.batch, device=layout.device
    )
