"""oasis-torchrl: Decart's Oasis action-to-video world model in the PyTorch robot-learning stack.

Sub-packages, one concern each: ``client`` (A2V client and session pool), ``sim`` (the embedded
procedural A2V server), ``envs`` (TorchRL and Gymnasium envs), ``rewards``, ``data`` (LeRobot
datasets), ``viz`` (rerun), ``models`` (the driving network), ``train`` (PPO, BC, evaluation),
``distributed`` (Ray collection), ``commands`` (the ``oasis-torchrl`` CLI).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("oasis-torchrl")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"
