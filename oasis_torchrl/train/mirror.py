"""Mirror augmentation: demonstrations and replayed observations reflected left to right.

The camera rig is symmetric (``left_forward`` and ``right_forward`` yawed 45 degrees to either
side of ``front``) and the worlds hold still, so a demonstration reflected left to right is a
demonstration in the mirrored world: every camera's frames flipped, the left and right cameras
swapped, steering negated, and in the privileged state the signed lateral fields negated and the
left and right fields swapped. It doubles the scenes a clone learns to see from, and it balances
the lane changes between the sides (the autopilot prefers the left of two free lanes, so right
ones are rare in its demonstrations).

One :class:`Mirror` serves both layouts the project trains on: behaviour cloning's raw LeRobot
batches (dicts of ``observation.images.<camera>`` ``[B, T, 3, H, W]``) and PPO's TensorDicts
(``("frame_stack", <camera>)`` ``[B, depth, H, W, 3]``, the auxiliary replay's minibatches).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TypeVar

import torch

from oasis_torchrl.models.privileged import PRIVILEGED_KEY
from oasis_torchrl.protocol import CAMERAS

Key = str | tuple[str, ...]
"""A batch key: ``"<prefix>.<camera>"`` in a dict, ``(<prefix>, <camera>)`` in a TensorDict."""
Batch = TypeVar("Batch")

MIRRORED_CAMERA = dict(zip(CAMERAS, reversed(CAMERAS), strict=True))
"""The camera that sees, in the mirrored world, what each camera sees (the rig is symmetric)."""
SIGNED_FIELDS = frozenset({"lateral_offset", "heading_error", "lane_offset"})
"""Privileged fields measured to one side (+ left): a reflection negates them."""
_SIDES = ("_left", "_right")


def mirrored_field(name: str) -> str:
    """The privileged field that holds, in the mirrored world, what ``name`` holds.

    Example:
        >>> mirrored_field("lane_obstacle_distance_left"), mirrored_field("speed")
        ('lane_obstacle_distance_right', 'speed')
    """
    for side, other in (_SIDES, _SIDES[::-1]):
        if name.endswith(side):
            return name[: -len(side)] + other
    return name


class Mirror:
    """Reflect a random share of a batch left to right.

    Args:
        image_keys: the batch's camera keys, each naming a camera of :data:`MIRRORED_CAMERA`
            (``"<prefix>.<camera>"`` or ``(<prefix>, <camera>)``).
        privileged_names: the fields of the batch's privileged state, in order (None: the
            batch has none).
        share: the probability that a sample is reflected.
        generator: the random draws' generator (None: torch's global one).
        steering_keys: the ``[..., 2k]`` ``[throttle, steering, ...]`` entries whose steering is
            negated (those absent from a batch are skipped).
        privileged_key: the privileged state's entry.
        width_dim: the images' width dimension (-1 channels-first, -2 channels-last).

    Raises:
        ValueError: a camera or a privileged field without a mirrored counterpart.

    Example:
        >>> mirror = Mirror(["observation.images.left_forward", "observation.images.front",
        ...                  "observation.images.right_forward"], ["lane_offset", "lanes_left",
        ...                  "lanes_right"], share=1.0, steering_keys=["action"])
        >>> batch = {"observation.images.left_forward": torch.zeros(1, 1, 3, 2, 2),
        ...          "observation.images.front": torch.arange(4.0).reshape(1, 1, 1, 2, 2),
        ...          "observation.images.right_forward": torch.ones(1, 1, 3, 2, 2),
        ...          "action": torch.tensor([[[1.0, 0.3]]]),
        ...          "privileged_state": torch.tensor([[0.5, 1.0, 0.0]])}
        >>> out = mirror(batch)
        >>> out["observation.images.front"].flatten().tolist()
        [1.0, 0.0, 3.0, 2.0]
        >>> out["observation.images.left_forward"].mean().item()
        1.0
        >>> out["action"].tolist(), out["privileged_state"].tolist()
        ([[[1.0, -0.30000001192092896]]], [[-0.5, 0.0, 1.0]])
    """

    def __init__(
        self,
        image_keys: Sequence[Key],
        privileged_names: Sequence[str] | None,
        share: float = 0.5,
        generator: torch.Generator | None = None,
        *,
        steering_keys: Sequence[Key] = (),
        privileged_key: Key = PRIVILEGED_KEY,
        width_dim: int = -1,
    ) -> None:
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"the mirrored share must be in [0, 1], got {share}")
        self.share = share
        self.generator = generator
        self.steering_keys = list(steering_keys)
        self.privileged_key = privileged_key
        self.width_dim = width_dim
        self.partner = {key: _mirrored_image_key(key) for key in image_keys}
        missing = sorted(map(str, set(self.partner.values()) - set(image_keys)))
        if missing:
            raise ValueError(f"mirroring needs the cameras {missing} beside {list(image_keys)}")
        self.field_order: torch.Tensor | None = None
        self.field_signs: torch.Tensor | None = None
        if privileged_names is not None:
            self.field_order, self.field_signs = _mirrored_fields(list(privileged_names))

    def __call__(self, batch: Batch) -> Batch:
        """A shallow copy of ``batch`` (a dict or a TensorDict) with each sample reflected with
        probability ``share``."""
        out = batch.copy()
        some = next(iter(self.partner))
        flip = torch.rand(batch[some].shape[0], generator=self.generator) < self.share
        if not flip.any():
            return out
        for key, partner in self.partner.items():
            out[key] = _where(flip, batch[partner].flip(self.width_dim), batch[key])
        for key in self.steering_keys:
            actions = batch.get(key, None)
            if actions is not None:
                out[key] = _where(flip, _negated_steering(actions), actions)
        state = batch.get(self.privileged_key, None)
        if self.field_order is not None and state is not None:
            mirrored = state[..., self.field_order] * self.field_signs
            out[self.privileged_key] = _where(flip, mirrored, state)
        return out


def _mirrored_image_key(key: Key) -> Key:
    prefix, camera = (key[:-1], key[-1]) if isinstance(key, tuple) else key.rpartition(".")[::2]
    if camera not in MIRRORED_CAMERA:
        raise ValueError(
            f"cannot mirror the camera of {key!r}: the mirror knows {sorted(MIRRORED_CAMERA)}"
        )
    if isinstance(key, tuple):
        return (*prefix, MIRRORED_CAMERA[camera])
    return f"{prefix}.{MIRRORED_CAMERA[camera]}"


def _mirrored_fields(names: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
    """Each field's source index in the mirrored world and its sign."""
    unpaired = [name for name in names if mirrored_field(name) not in names]
    if unpaired:
        raise ValueError(f"cannot mirror the privileged fields {unpaired}: no counterpart")
    order = torch.tensor([names.index(mirrored_field(name)) for name in names])
    signs = torch.tensor([-1.0 if name in SIGNED_FIELDS else 1.0 for name in names])
    return order, signs


def _negated_steering(actions: torch.Tensor) -> torch.Tensor:
    """``[..., 2k]`` ``[throttle, steering, ...]`` actions with every steering negated."""
    signs = torch.ones(actions.shape[-1], dtype=actions.dtype)
    signs[1::2] = -1.0
    return actions * signs


def _where(flip: torch.Tensor, mirrored: torch.Tensor, original: torch.Tensor) -> torch.Tensor:
    return torch.where(flip.view(-1, *[1] * (original.dim() - 1)), mirrored, original)
