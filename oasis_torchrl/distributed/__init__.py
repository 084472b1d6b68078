"""Scale-out: rollouts and recording on Ray through TorchRL's ``RayCollector``.

- :class:`RayCollectionConfig`: the ``ray`` config section.
- :class:`RayCollection`: the distributed collector over OasisEnvs, whose worker envs come
  from :func:`env_factory`.
- :class:`ShardRecorder`: one worker's LeRobot shard; :func:`merge_shards`: one dataset from all.
- :func:`record_on_ray`: record a dataset on Ray workers and merge it (``record --ray``).
- :class:`ClusterStartupError`: a cluster that cannot be reached or cannot place the
  collectors within ``ray.startup_timeout_s``.
"""

from oasis_torchrl.config.ray import RayCollectionConfig
from oasis_torchrl.distributed.merge import complete_shards, merge_shards
from oasis_torchrl.distributed.placement import ClusterStartupError
from oasis_torchrl.distributed.ray_collection import (
    RayCollection,
    WorkerLostError,
    env_factory,
)
from oasis_torchrl.distributed.ray_recording import RayRecording, record_on_ray
from oasis_torchrl.distributed.sharded_recording import ShardRecorder

__all__ = [
    "ClusterStartupError",
    "RayCollection",
    "RayCollectionConfig",
    "RayRecording",
    "ShardRecorder",
    "WorkerLostError",
    "complete_shards",
    "env_factory",
    "merge_shards",
    "record_on_ray",
]
