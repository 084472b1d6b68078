"""oasis-torchrl: Decart's Oasis action-to-video world model in the PyTorch robot-learning stack.

Sub-packages, one concern each: ``client`` (A2V client and session pool), ``sim`` (the embedded
procedural A2V server), ``envs`` (TorchRL env), ``rewards``.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("oasis-torchrl")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"
