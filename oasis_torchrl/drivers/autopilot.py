"""The embedded server's privileged expert as a driver."""

from __future__ import annotations

import torch
from tensordict import TensorDictBase

from oasis_torchrl.drivers.base import Driver

EXPERT_ACTION = "expert_action"


class Autopilot(Driver):
    """The embedded server's privileged expert: drives with each row's ``"expert_action"``.

    The embedded server runs an autopilot beside every session's world (it knows the scene and
    the car's exact state) and sends the chunk it would take next with the ground truth; an env
    built with ``expert=True`` exposes it as ``"expert_action"``. Rows without one (NaN: the
    row's session was lost) get zeros.

    Args:
        chunk_actions: see :class:`Driver`.

    Example:
        >>> from tensordict import TensorDict
        >>> expert = torch.tensor([[[0.6, 0.1]] * 4, [[float("nan")] * 2] * 4])
        >>> Autopilot()(TensorDict(expert_action=expert, batch_size=[2]))["action"][:, 0]
        tensor([[0.6000, 0.1000],
                [0.0000, 0.0000]])
    """

    needs_expert = True

    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """The expert's next chunk for every row."""
        expert = td.get(EXPERT_ACTION, None)
        if expert is None:
            raise KeyError(
                f"the autopilot drives with {EXPERT_ACTION!r}, which only the embedded server "
                "sends, to an env built with expert=True (endpoint 'local', or an "
                "'oasis-torchrl serve' server)"
            )
        return torch.nan_to_num(expert, nan=0.0)
