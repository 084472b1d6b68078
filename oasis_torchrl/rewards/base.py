"""The reward-module protocol the batched env calls every step, and the helpers rewards share.

The env calls ``reward_module(td)`` after each step, with the "next" observation keys at the root
of ``td`` (batch size ``[N]``), and ``reward_module.reset(mask)`` when rows restart. A reward module
answers with a TensorDict of batch size ``[N]`` holding ``"reward"`` float32 ``[N, 1]``,
optionally ``"terminated"`` bool ``[N, 1]``, and each named term of its formula under
``("reward_terms", name)`` float32 ``[N, 1]``. A module may name those terms in a ``terms``
attribute (tuple of str), which the env reads to declare its reward-term specs.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Protocol, runtime_checkable

import torch
from tensordict import NestedKey, TensorDict, TensorDictBase

RewardFn = Callable[[TensorDictBase], torch.Tensor]


@runtime_checkable
class RewardModule(Protocol):
    """What the env calls: ``module(td) -> TensorDict`` every step, ``module.reset(mask)``.

    Optional (not part of the protocol check): ``terms``, the names under ``"reward_terms"``.

    >>> isinstance(as_reward_module(lambda td: td["action"][:, :, 0].mean(-1)), RewardModule)
    True
    """

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        """Reward (and optionally termination and terms) for the step that produced ``td``."""
        ...

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Forget per-row state for the rows where ``mask`` is True (all rows when None)."""
        ...


class CallableReward:
    """A stateless :class:`RewardModule` around ``fn(td) -> Tensor[N] or [N, 1]``.

    >>> module = CallableReward(lambda td: td["action"][:, :, 0].mean(-1))
    >>> td = TensorDict({"action": torch.ones(3, 4, 2)}, batch_size=[3])
    >>> module(td)["reward"].shape
    torch.Size([3, 1])
    """

    terms: tuple[str, ...] = ()

    def __init__(self, fn: RewardFn) -> None:
        if not callable(fn):
            raise TypeError(f"fn must be callable as fn(td) -> Tensor, got {type(fn).__name__}")
        self.fn = fn

    def __call__(self, td: TensorDictBase) -> TensorDict:
        """Call ``fn`` and wrap its per-row rewards as ``"reward"`` float32 ``[N, 1]``."""
        batch = batch_rows(td)
        reward = self.fn(td)
        if not isinstance(reward, torch.Tensor):
            raise TypeError(f"reward fn must return a torch.Tensor, got {type(reward).__name__}")
        if reward.shape not in ((batch,), (batch, 1)):
            raise ValueError(
                f"reward fn must return shape [{batch}] or [{batch}, 1], got {list(reward.shape)}"
            )
        return reward_output(reward.reshape(batch))

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Nothing to forget: a plain callable holds no per-row state."""


class NoReward:
    """A :class:`RewardModule` that scores nothing: reward 0, no terms, never terminates.

    For an env whose caller reads no reward (a LeRobot robot): the default reward on frames
    alone runs a network every step.

    >>> NoReward()(TensorDict({}, batch_size=[2]))["reward"].tolist()
    [[0.0], [0.0]]
    """

    terms: tuple[str, ...] = ()

    def __call__(self, td: TensorDictBase) -> TensorDict:
        """Zero reward for every row."""
        return reward_output(torch.zeros(batch_rows(td)))

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Nothing to forget."""


def as_reward_module(fn: RewardModule | RewardFn) -> RewardModule:
    """Return ``fn`` itself if it is already a :class:`RewardModule`, else wrap it.

    >>> module = as_reward_module(lambda td: torch.zeros(td.shape[0]))
    >>> module(TensorDict({}, batch_size=[2]))["reward"].tolist()
    [[0.0], [0.0]]
    """
    if isinstance(fn, RewardModule):
        return fn
    return CallableReward(fn)


def batch_rows(td: TensorDictBase) -> int:
    """The row count ``N`` of a TensorDict with batch size ``[N]``.

    >>> batch_rows(TensorDict({}, batch_size=[5]))
    5
    """
    if td.batch_dims != 1:
        raise ValueError(f"rewards expect a TensorDict with batch size [N], got {list(td.shape)}")
    return td.shape[0]


def get_entry(td: TensorDictBase, key: NestedKey, owner: str) -> torch.Tensor:
    """``td[key]``, or a KeyError naming ``owner``, the key and the keys that are there.

    >>> td = TensorDict({"action": torch.zeros(2, 4, 2)}, batch_size=[2])
    >>> get_entry(td, "action", "doc").shape
    torch.Size([2, 4, 2])
    """
    value = td.get(key, None)
    if value is None:
        available = ", ".join(str(k) for k in td.keys(include_nested=True, leaves_only=True))
        raise KeyError(f"{owner} needs td[{key!r}], which is missing; td holds: {available}")
    return value


def reward_output(
    reward: torch.Tensor,
    terms: Mapping[str, torch.Tensor] | None = None,
    terminated: torch.Tensor | None = None,
) -> TensorDict:
    """Pack per-row ``[N]`` tensors into the reward TensorDict the env expects.

    >>> out = reward_output(torch.ones(2), {"forward": torch.ones(2)}, torch.tensor([True, False]))
    >>> out["reward"].shape, out["terminated"].dtype, out["reward_terms", "forward"].shape
    (torch.Size([2, 1]), torch.bool, torch.Size([2, 1]))
    """
    batch = reward.shape[0]
    out = TensorDict({"reward": reward.reshape(batch, 1).float()}, batch_size=[batch])
    if terminated is not None:
        out["terminated"] = terminated.reshape(batch, 1).bool()
    for name, value in (terms or {}).items():
        out["reward_terms", name] = value.reshape(batch, 1).float()
    return out


class RowState:
    """One value per row of a batched reward (a scalar, or a tensor of ``shape``), created on
    first use and reset per row.

    >>> heading = RowState("heading")
    >>> heading.write(heading.read(3, torch.device("cpu")) + torch.tensor([1.0, 2.0, 3.0]))
    >>> heading.reset(torch.tensor([True, False, True]))
    >>> heading.read(3, torch.device("cpu")).tolist()
    [0.0, 2.0, 0.0]
    >>> action = RowState("action", shape=(2,))
    >>> action.write(torch.ones(2, 2))
    >>> action.reset(torch.tensor([False, True]))
    >>> action.read(2, torch.device("cpu")).tolist()
    [[1.0, 1.0], [0.0, 0.0]]
    """

    def __init__(
        self, name: str, dtype: torch.dtype = torch.float32, shape: tuple[int, ...] = ()
    ) -> None:
        self.name = name
        self.dtype = dtype
        self.shape = shape
        self._value: torch.Tensor | None = None

    def read(self, batch: int, device: torch.device) -> torch.Tensor:
        """The current values ``[batch, *shape]`` on ``device`` (zeros before the first
        write)."""
        if self._value is None:
            return torch.zeros(batch, *self.shape, dtype=self.dtype, device=device)
        if self._value.shape[0] != batch:
            raise ValueError(
                f"{self.name} state holds {self._value.shape[0]} rows but td has {batch}; "
                "call reset() (all rows) when the batch size changes"
            )
        return self._value.to(device)

    def write(self, value: torch.Tensor) -> None:
        """Store ``value`` ``[N, *shape]`` as the new per-row state."""
        self._value = value.detach().to(self.dtype)

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Zero the rows where ``mask`` (bool ``[N]`` or ``[N, 1]``) is True; None zeroes all."""
        if mask is None or self._value is None:
            self._value = None
            return
        rows = self._value.shape[0]
        if mask.dtype != torch.bool or mask.numel() != rows:
            raise ValueError(
                f"reset mask must be a bool tensor of shape [{rows}] or [{rows}, 1], "
                f"got dtype {mask.dtype} and shape {list(mask.shape)}"
            )
        rows_mask = mask.reshape(rows, *(1 for _ in self.shape)).to(self._value.device)
        self._value = self._value.masked_fill(rows_mask, 0)
