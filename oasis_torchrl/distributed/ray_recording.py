"""Record a LeRobot dataset on Ray: every worker drives its own sessions into its own shard, then
the shards are merged into one dataset.

The driver travels to the workers as a picklable factory (a
:class:`~oasis_torchrl.drivers.DriverSpec`) and is built there. Workers record up to their share
of the requested episodes and send back only the batch shape, so frames never cross the
network. Whatever ends the run (done, a lost worker, Ctrl-C), the finalized shard parts are
merged into the output; the shards are deleted only after a complete run (unless kept), and
otherwise the log names where they are. A worker lost mid-part loses that part's episodes (use
``ray.part_batches`` to bound that); the others' shares are not raised to make up for it.
"""

from __future__ import annotations

import logging
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tensordict import TensorDictBase
from torchrl.envs import EnvBase

from oasis_torchrl.config.ray import RayCollectionConfig
from oasis_torchrl.data.loading import default_repo_id
from oasis_torchrl.distributed.merge import merge_shards
from oasis_torchrl.distributed.ray_collection import RayCollection, WorkerLostError

logger = logging.getLogger(__name__)

Policy = Callable[[TensorDictBase], TensorDictBase]


def check_fresh_outputs(shard_root: Path, output: Path) -> None:
    """Refuse an existing output dataset or a shard root holding anything (earlier shards would
    be merged into this run).

    Example:
        >>> import tempfile
        >>> root = Path(tempfile.mkdtemp())
        >>> check_fresh_outputs(root / "drives.shards", root / "drives")
        >>> check_fresh_outputs(root / "drives.shards", root)
        Traceback (most recent call last):
        ...
        FileExistsError: output dataset ... already exists; pick a new folder
    """
    if output.exists():
        raise FileExistsError(f"output dataset {output} already exists; pick a new folder")
    if shard_root.exists() and any(shard_root.iterdir()):
        raise FileExistsError(
            f"shard root {shard_root} is not empty (shards of an earlier run?); merge them with "
            "oasis_torchrl.distributed.merge_shards, remove them or pick another shard root"
        )


@dataclass(frozen=True)
class RayRecording:
    """What a Ray recording left.

    Attributes:
        output: the merged dataset.
        episodes: episodes in it.
        shard_root: the shards (deleted after a complete run unless kept).
        lost_workers: workers lost during the run.
        stopped: a lost worker stopped the run (``on_failure="stop"``).

    Example:
        >>> RayRecording(Path("drives"), 8, Path("drives.shards"), [], False).complete
        True
    """

    output: Path
    episodes: int
    shard_root: Path
    lost_workers: list[int]
    stopped: bool

    @property
    def complete(self) -> bool:
        """No worker was lost."""
        return not self.lost_workers


def record_on_ray(
    config: RayCollectionConfig,
    create_env: Callable[[], EnvBase],
    driver: Callable[[], Policy],
    output: str | Path,
    *,
    episodes: int,
    batch_steps: int,
    seed: int = 0,
    repo_id: str | None = None,
    recorder_kwargs: dict[str, Any] | None = None,
    keep_shards: bool = False,
    progress: Callable[[int], None] | None = None,
) -> RayRecording:
    """Record ``episodes`` episodes on Ray workers into shards under ``config.shard_root``, then
    merge them into the dataset ``output``.

    A lost worker is handled as ``config.on_failure`` says; either way (and on Ctrl-C) the
    finalized shard parts are merged into ``output`` and the shards kept.

    Args:
        config: the Ray settings; ``shard_root`` is required and must be empty or absent.
        create_env: picklable constructor of one worker env (see
            :func:`~oasis_torchrl.distributed.env_factory`).
        driver: picklable factory of the driving policy, called in each worker.
        output: the merged dataset folder (must not exist).
        episodes: episodes to record, split evenly over the workers (episodes still running
            when a worker has its share are dropped).
        batch_steps: env steps of each row per Ray batch (how often workers report).
        seed: run seed (each worker's env gets its own seed derived from it).
        repo_id: LeRobot repo id of the merged dataset (default ``local/<folder name>``).
        recorder_kwargs: further :class:`~oasis_torchrl.data.LeRobotRecorder` arguments of the
            shards (``fps``, ``image_size``, ``vcodec``, ``crf``).
        keep_shards: keep the shards after a complete run's merge.
        progress: called with the episodes recorded so far after every batch.

    Example:
        >>> from oasis_torchrl.config import EnvConfig
        >>> from oasis_torchrl.distributed import env_factory
        >>> from oasis_torchrl.drivers import DriverSpec
        >>> config = RayCollectionConfig(num_collectors=2, shard_root="drives.shards")
        >>> record_on_ray(config, env_factory(EnvConfig(max_steps=8), config),
        ...               DriverSpec("autopilot"), "drives", episodes=16, batch_steps=8
        ...               ).episodes  # doctest: +SKIP
        16
    """
    if config.shard_root is None:
        raise ValueError("record_on_ray needs ray.shard_root (where the workers write)")
    if batch_steps < 1:
        raise ValueError(f"batch_steps must be >= 1, got {batch_steps}")
    shard_root, output = Path(config.shard_root), Path(output)
    check_fresh_outputs(shard_root, output)
    collection = RayCollection(
        config,
        create_env,
        None,
        policy_factory=driver,
        frames_per_batch=config.total_sessions * batch_steps,
        total_frames=sys.maxsize,  # the episode count ends the run, as in a single process
        seed=seed,
        recorder_kwargs={**(recorder_kwargs or {}), "keep_unfinished": False},
        max_episodes=episodes,
        batch_keys=(),
    )
    stopped = False
    try:
        with collection:
            for _ in collection:
                if progress is not None:
                    progress(collection.recorded_episodes)
    except WorkerLostError:  # logged by the collection, the other shards finalized
        stopped = True
    except BaseException:
        _merge_kept(shard_root, output, repo_id)
        raise
    lost = list(collection.lost_workers)
    if lost:
        merged = _merge_kept(shard_root, output, repo_id)
    else:
        merge_shards(shard_root, output, repo_id=repo_id)
        merged = _episodes_in(output)
        if not keep_shards:
            shutil.rmtree(shard_root)
    return RayRecording(output, merged, shard_root, lost, stopped)


def _merge_kept(shard_root: Path, output: Path, repo_id: str | None) -> int:
    """After a run that ended early or lost a worker: merge what was finalized, keep the shards
    and say where they are; returns the episodes merged."""
    try:
        merge_shards(shard_root, output, repo_id=repo_id)
    except Exception as error:  # often raised while another error is handled: do not mask it
        logger.error("nothing merged (%s); the shards stay in %s", error, shard_root)
        return 0
    merged = _episodes_in(output)
    logger.warning(
        "the run ended early: its %d finalized episodes are merged into %s; the shards stay in %s",
        merged,
        output,
        shard_root,
    )
    return merged


def _episodes_in(root: Path) -> int:
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    return LeRobotDatasetMetadata(default_repo_id(root), root=root).total_episodes
