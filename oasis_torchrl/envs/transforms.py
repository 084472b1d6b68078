"""TorchRL transforms of the Oasis env: the privileged state an asymmetric critic reads."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs import Transform

from oasis_torchrl.models.actor_critic import CRITIC_INPUTS

PRIVILEGED_FIELDS = (
    "speed",
    "lateral_offset",
    "heading_error",
    "obstacle_distance",
    "obstacle_distance_left",
    "obstacle_distance_right",
)
_PRIVILEGED_SCALE = torch.tensor([10.0, 4.0, 1.0, 60.0, 60.0, 60.0])
"""Rough magnitudes: m/s, m, rad, then metres (the obstacle distances are capped at 60 m, as
where no obstacle is: the critic and the auxiliary head need to know which lane is open)."""
_FIRST_DISTANCE = PRIVILEGED_FIELDS.index("obstacle_distance")


class PrivilegedState(Transform):
    """Writes ``"critic_inputs"`` ``[N, 6]``: the last frame's ground truth in
    :data:`PRIVILEGED_FIELDS` (speed, lateral offset, heading error, obstacle distances ahead,
    one lane left and one lane right), scaled to about unit size.

    For an asymmetric actor-critic on the embedded server: the critic may use the simulator's
    state, the actor (what is deployed) only sees the cameras and the previous action.

    Example:
        >>> from tensordict import TensorDict
        >>> truth = {field: torch.full((2, 4), 2.0) for field in PRIVILEGED_FIELDS}
        >>> truth["obstacle_distance_right"][0] = float("inf")
        >>> out = PrivilegedState()(TensorDict({"truth": truth}, [2]))
        >>> out["critic_inputs"][:, -1].tolist()
        [1.0, 0.03333333507180214]
    """

    def __init__(self) -> None:
        in_keys = [("truth", field) for field in PRIVILEGED_FIELDS]
        super().__init__(in_keys=in_keys, out_keys=[CRITIC_INPUTS])

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        last = torch.stack([next_tensordict.get(key)[..., -1] for key in self.in_keys], dim=-1)
        distances = last[..., _FIRST_DISTANCE:]
        distances.copy_(distances.nan_to_num(posinf=60.0).clamp(max=60.0))
        scale = _PRIVILEGED_SCALE.to(last.device)
        return next_tensordict.set(CRITIC_INPUTS, (last / scale).nan_to_num(0.0))

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
