"""Turn a policy spec (a name or a path) into a TorchRL-style policy ``td -> td``.

Specs: ``autopilot`` (the embedded simulator's privileged expert), ``constant:<driver spec>``
(``constant:throttle=1.0,steering=0.0``; any :class:`~oasis_torchrl.drivers.ScriptedDriver`
spec), a PPO checkpoint file, or a LeRobot ``oasis`` policy folder (behaviour cloning output).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tensordict import TensorDictBase

from oasis_torchrl.models import DrivingNet, make_actor_critic
from oasis_torchrl.train.checkpoint import load_net

Policy = Callable[[TensorDictBase], TensorDictBase]
AUTOPILOT = "autopilot"
CONSTANT = "constant:"


@dataclass
class PolicySource:
    """A loaded policy, the image size it wants (networks only) and its network, if any.

    Example:
        >>> load_policy("autopilot").net is None
        True
    """

    policy: Policy
    image_size: tuple[int, int] | None = None
    net: DrivingNet | None = None


def load_policy(spec: str | Path) -> PolicySource:
    """Load the policy a spec names.

    Example:
        >>> load_policy("constant:throttle=1.0").image_size is None
        True
        >>> load_policy("nowhere.pt")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: policy 'nowhere.pt' is neither 'autopilot', 'constant:<spec>' nor ...
    """
    from oasis_torchrl.drivers import Autopilot, ScriptedDriver

    text = str(spec)
    if text == AUTOPILOT:
        return PolicySource(Autopilot())
    if text.startswith(CONSTANT):
        return PolicySource(ScriptedDriver.from_spec(text.removeprefix(CONSTANT)))
    path = Path(text)
    if not path.exists():
        raise ValueError(
            f"policy {text!r} is neither {AUTOPILOT!r}, '{CONSTANT}<spec>' nor an existing path"
        )
    net = load_net(path).eval()
    return PolicySource(make_actor_critic(net).policy, tuple(net.config.image_size), net)
