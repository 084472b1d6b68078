"""Drivers: TorchRL-policy-like callables ``td -> td`` that set ``"action"``, and the one
grammar that names them (:func:`load_driver`).

- :class:`Autopilot`: the embedded server's privileged expert; the server runs it next to each
  session's world and sends its next chunk with the ground truth, which an env built with
  ``expert=True`` exposes as ``"expert_action"`` (a driver's :attr:`~Driver.needs_expert`).
- :class:`ScriptedDriver`: constant or sinusoidal throttle and steering from a small spec.
- :class:`PolicyDriver`: a torch policy: the driving network of a LeRobot policy folder or a PPO
  checkpoint, any TorchScript / ``torch.save``d module, or a policy served by a policy server
  (``grpc://host:port``, :class:`~oasis_torchrl.remote.RemotePolicy`).
- :class:`~oasis_torchrl.drivers.lerobot.LeRobotDriver`: any other LeRobot policy folder (``act``,
  ``diffusion``, plugins, ...) with its saved processors, four ``select_action`` calls per chunk.
- ``pretrained:NAME``: a policy the package ships (:func:`shipped_policies`,
  :func:`pretrained_path`), loaded as its LeRobot policy folder.
- :class:`DriverSpec`: any of them named by a spec string, picklable, built where it drives
  (e.g. in a Ray worker: a loaded TorchScript policy does not pickle, its file name does).

Every driver returns action chunks ``[N, 4, 2]`` (or ``[N, 2]`` for an env built with
``chunk_actions=False``).
"""

from oasis_torchrl.drivers.autopilot import EXPERT_ACTION, Autopilot
from oasis_torchrl.drivers.base import Driver, bounded
from oasis_torchrl.drivers.folders import export_lerobot, load_net, net_from_lerobot
from oasis_torchrl.drivers.lerobot import LeRobotDriver
from oasis_torchrl.drivers.loading import AUTOPILOT, GRAMMAR, SCRIPTED, DriverSpec, load_driver
from oasis_torchrl.drivers.policy import PolicyDriver, load_module
from oasis_torchrl.drivers.pretrained import pretrained_path, shipped_policies
from oasis_torchrl.drivers.scripted import ScriptedDriver

__all__ = [
    "AUTOPILOT",
    "EXPERT_ACTION",
    "GRAMMAR",
    "SCRIPTED",
    "Autopilot",
    "Driver",
    "DriverSpec",
    "LeRobotDriver",
    "PolicyDriver",
    "ScriptedDriver",
    "bounded",
    "export_lerobot",
    "load_driver",
    "load_module",
    "load_net",
    "net_from_lerobot",
    "pretrained_path",
    "shipped_policies",
]
