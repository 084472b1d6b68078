"""One grammar that names a driver (:func:`load_driver`) and its picklable form
(:class:`DriverSpec`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from oasis_torchrl.drivers.autopilot import Autopilot
from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.drivers.lerobot import LeRobotDriver, policy_type
from oasis_torchrl.drivers.policy import PolicyDriver
from oasis_torchrl.drivers.pretrained import resolve_pretrained
from oasis_torchrl.drivers.scripted import ScriptedDriver
from oasis_torchrl.remote import is_policy_url

AUTOPILOT = "autopilot"
SCRIPTED = ("scripted:", "constant:")
GRAMMAR = (
    "'autopilot', 'scripted:<script>' (or 'constant:<script>', e.g. "
    "'constant:throttle=1.0,steering=0.0'), a shipped policy ('pretrained:<name>', e.g. "
    "'pretrained:ppo-scratch'), the path of a saved policy (a LeRobot policy folder of any "
    "type LeRobot loads, a PPO checkpoint, a TorchScript or torch.save file), or a policy "
    "server ('grpc://host:port', 'grpcs://host:port' with TLS)"
)
NETWORK_POLICY_TYPE = "oasis"
"""The LeRobot policy type whose folders load as the driving network itself."""


def load_driver(
    spec: str | Path, *, in_keys: Sequence[str | tuple[str, ...]] | None = None
) -> Driver:
    """The driver a spec names (:data:`GRAMMAR`), everywhere a driver or policy is named:
    ``oasis-torchrl eval policy=``, ``record --driver``, the pipeline's references and learners.

    ``pretrained:NAME`` is the shipped policy's folder (:mod:`~oasis_torchrl.drivers.pretrained`).
    A LeRobot policy folder of type ``oasis`` loads as the driving network (:class:`PolicyDriver`,
    the TorchRL actor); any other type through LeRobot's factory and
    the processors saved with it (:class:`~oasis_torchrl.drivers.lerobot.LeRobotDriver`).

    Args:
        spec: the driver's name.
        in_keys: inputs of a plain saved module (see :class:`PolicyDriver`).

    Example:
        >>> type(load_driver("constant:throttle=1.0")).__name__
        'ScriptedDriver'
        >>> load_driver("nowhere.pt")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: driver 'nowhere.pt' is none of 'autopilot', 'scripted:<script>' ...
    """
    text = resolve_pretrained(str(spec))
    if text == AUTOPILOT:
        return Autopilot()
    for prefix in SCRIPTED:
        if text.startswith(prefix):
            return ScriptedDriver.from_spec(text.removeprefix(prefix))
    if is_policy_url(text):
        return PolicyDriver.remote(text)
    path = Path(text)
    if not path.exists():
        raise ValueError(f"driver {text!r} is none of {GRAMMAR}")
    if path.is_dir() and policy_type(path) != NETWORK_POLICY_TYPE:
        return LeRobotDriver.load(path)
    return PolicyDriver.load(path, in_keys=in_keys)


@dataclass(frozen=True)
class DriverSpec:
    """A driver named by plain values: picklable and small, so it can be shipped (to a Ray
    worker, say) and built there by calling it.

    Args:
        spec: the driver (:func:`load_driver`); a path is made absolute (a worker may run
            elsewhere).
        in_keys: inputs of a plain saved module (see :class:`PolicyDriver`).

    Example:
        >>> import pickle
        >>> spec = pickle.loads(pickle.dumps(DriverSpec("scripted:throttle=0.3")))
        >>> type(spec()).__name__
        'ScriptedDriver'
    """

    spec: str = AUTOPILOT
    in_keys: tuple[tuple[str, ...], ...] | None = None

    def __post_init__(self) -> None:
        if Path(self.spec).exists():
            object.__setattr__(self, "spec", str(Path(self.spec).absolute()))

    def __call__(self) -> Driver:
        """Build the driver."""
        return load_driver(self.spec, in_keys=self.in_keys)
