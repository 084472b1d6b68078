"""Rerun for oasis rollouts: see every rollout live or saved, and replay datasets.

- :class:`RolloutLogger`: log rollouts (plain function, collector hook, TorchRL transform,
  sync-client ``FrameConsumer``) to a viewer or an ``.rrd`` file; :class:`LogOptions` says what.
- :func:`default_blueprint`: the layout (cameras, time series, top-down view, one tab per row).
- :mod:`oasis_torchrl.viz.replay`: ``.rrd`` files, saved rollouts and LeRobot datasets to rerun
  (``oasis-torchrl view PATH``).

Needs the ``rerun`` extra (``rerun-sdk``).

>>> from oasis_torchrl.viz import LogOptions
>>> LogOptions().jpeg_quality
70
"""

from oasis_torchrl.viz.blueprint import default_blueprint
from oasis_torchrl.viz.hooks import RerunFrameConsumer, RerunTransform
from oasis_torchrl.viz.logger import RolloutLogger
from oasis_torchrl.viz.options import LogOptions
from oasis_torchrl.viz.paths import FRAME_TIMELINE, TIME_TIMELINE, RowPaths
from oasis_torchrl.viz.replay import load_rollout, save_rollout
from oasis_torchrl.viz.topdown import Window

__all__ = [
    "FRAME_TIMELINE",
    "TIME_TIMELINE",
    "LogOptions",
    "RerunFrameConsumer",
    "RerunTransform",
    "RolloutLogger",
    "RowPaths",
    "Window",
    "default_blueprint",
    "load_rollout",
    "save_rollout",
]
