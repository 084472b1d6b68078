"""LeRobot datasets: export rollouts, import human recordings, load for behaviour cloning.

Everything is written through LeRobot's own API (LeRobotDataset v3.0), so the datasets open
with ``LeRobotDataset``, train with ``lerobot-train`` and play in ``lerobot-dataset-viz``.
Needs the ``lerobot`` extra.

- :class:`LeRobotRecorder`: ``env.rollout`` output and collector batches -> one episode per env
  episode (also a collector hook); the row mapping is in :mod:`oasis_torchrl.data.chunk_rows`.
- :func:`import_recordings`: the reference SDK's ``episode_*/manifest.jsonl`` recordings.
- :func:`open_for_bc`: a dataset whose samples carry the next actions of a chunk policy.

>>> from oasis_torchrl.data import LeRobotRecorder, import_recordings, open_for_bc
>>> LeRobotRecorder("drives").fps
20
"""

from oasis_torchrl.data.chunk_rows import batch_to_rows, infer_layout
from oasis_torchrl.data.features import DatasetLayout, build_features
from oasis_torchrl.data.importer import ImportReport, RecordingError, import_recordings
from oasis_torchrl.data.loading import action_delta_timestamps, default_video_backend, open_for_bc
from oasis_torchrl.data.recorder import LeRobotRecorder

__all__ = [
    "DatasetLayout",
    "ImportReport",
    "LeRobotRecorder",
    "RecordingError",
    "action_delta_timestamps",
    "batch_to_rows",
    "build_features",
    "default_video_backend",
    "import_recordings",
    "infer_layout",
    "open_for_bc",
]
