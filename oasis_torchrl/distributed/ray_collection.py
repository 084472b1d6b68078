"""Rollouts on Ray: TorchRL's :class:`~torchrl.collectors.distributed.RayCollector` over OasisEnvs.

Every Ray actor runs a TorchRL collector over its own env(s); each ``OasisEnv`` opens its own
channel in the actor (and, for ``endpoint="local"``, its own embedded server, or all share the
``server_address`` of one ``oasis-torchrl serve``). Every actor's env is seeded differently (from
one run seed), so workers never drive the same worlds. Weights travel as TorchRL sends them (its Ray
weight sync, met at each node's cluster address rather than its hostname's:
:func:`~oasis_torchrl.compat.ray_weight_sync_scheme`). :class:`RayCollection` adds what a run needs
around it: per-worker LeRobot shards (optionally up to an episode count split over the workers), and
a lost worker reported and then either dropped (``on_failure="continue"``) or the run stopped
cleanly (``"stop"``), with every surviving shard finalized either way. In sync mode the round in
which a worker dies is not yielded (the survivors' part of it is still recorded in their shards).
The collectors are reserved together before any starts, and a cluster that cannot be reached or
cannot place them stops the run within ``ray.startup_timeout_s`` (:mod:`.placement`); closing shuts
the live collectors down (their envs closed, every session finished) before Ray kills them.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import ray
from omegaconf import DictConfig, OmegaConf
from ray.exceptions import RayActorError
from ray.util.placement_group import remove_placement_group
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torch import nn
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.collectors.distributed import RayCollector
from torchrl.envs import EnvBase

from oasis_torchrl.closing import Closing
from oasis_torchrl.compat import drop_ray_collectors, ray_weight_sync_scheme
from oasis_torchrl.config.env import EnvConfig
from oasis_torchrl.config.ray import RayCollectionConfig
from oasis_torchrl.distributed.placement import (
    ClusterStartupError,
    check_reachable,
    collector_nodes,
    collector_options,
    reserve_collectors,
)
from oasis_torchrl.distributed.sharded_recording import ShardRecorder

logger = logging.getLogger(__name__)

PING_TIMEOUT_S = 60.0
"""How long a live worker may take to answer the liveness probe after a failure."""
CLOSE_TIMEOUT_S = 60.0
"""How long the live workers may take to close their envs (finishing every session)."""


class WorkerLostError(RuntimeError):
    """A Ray collector worker died and the run was stopped (``on_failure="stop"``)."""


def env_factory(
    env: EnvConfig | DictConfig, config: RayCollectionConfig, **make_kwargs: Any
) -> functools.partial[EnvBase]:
    """A picklable constructor of one worker's env (:func:`~oasis_torchrl.envs.make_env` of the
    ``env`` settings and ``make_kwargs``) with ``sessions_per_env`` rows; ``server_address``,
    when set, replaces ``env.endpoint`` (with ground truth on: it is an embedded server).

    Example:
        >>> from oasis_torchrl.config import EnvConfig
        >>> make = env_factory(EnvConfig(), RayCollectionConfig(sessions_per_env=2))
        >>> make().batch_size
        torch.Size([2])
    """
    from oasis_torchrl.envs.factory import make_env

    settings = OmegaConf.to_object(env) if isinstance(env, DictConfig) else env
    if config.server_address is not None:
        settings = replace(settings, endpoint=config.server_address)
        make_kwargs = {**make_kwargs, "ground_truth": True}
    return functools.partial(make_env, settings, num_envs=config.sessions_per_env, **make_kwargs)


def worker_seeds(seed: int, workers: int) -> list[int]:
    """Independent env seeds of ``workers`` Ray workers, all derived from the run's ``seed``.

    Example:
        >>> first, second = worker_seeds(0, 2)
        >>> first != second and worker_seeds(0, 2) == [first, second]
        True
    """
    children = np.random.SeedSequence(seed).spawn(workers)
    return [int(child.generate_state(1)[0]) for child in children]


def split_evenly(total: int, parts: int) -> list[int]:
    """``total`` split into ``parts`` shares differing by at most one, the larger ones first.

    Example:
        >>> split_evenly(7, 3)
        [3, 2, 2]
    """
    share, rest = divmod(total, parts)
    return [share + (part < rest) for part in range(parts)]


@dataclass(frozen=True)
class SeededEnvFactory:
    """A picklable env constructor that seeds the env before the collector's first reset.

    Example:
        >>> make = SeededEnvFactory(env_factory(EnvConfig(), RayCollectionConfig()), seed=3)
        >>> make.seed
        3
    """

    make_env: Callable[[], EnvBase]
    seed: int

    def __call__(self) -> EnvBase:
        """Build the env and seed it."""
        env = self.make_env()
        env.set_seed(self.seed)
        return env


class RayCollection(Closing):
    """A TorchRL Ray collector over OasisEnvs, with sharded recording and failure handling.

    Iterate it like a collector: in ``sync`` mode each batch stacks one ``[N, T]`` batch per
    live collector (``[C, N, T]``); otherwise batches come first-ready, ``[N, T]`` each.

    Args:
        config: where and how wide to run.
        create_env: picklable env constructor (see :func:`env_factory`).
        policy: the policy (an ``nn.Module``: its weights are what workers receive); None
            with ``policy_factory``.
        frames_per_batch: env steps per yielded batch (all rows, all collectors).
        total_frames: env steps of the whole run (at most).
        policy_factory: picklable callable building the policy in each worker, for a policy
            that does not pickle or carries no weights (e.g. a
            :class:`~oasis_torchrl.drivers.DriverSpec`).
        seed: run seed; worker ``i``'s env gets ``worker_seeds(seed, C)[i]``.
        recorder_kwargs: :class:`~oasis_torchrl.data.LeRobotRecorder` arguments of the shards
            (used when ``config.shard_root`` is set).
        max_episodes: stop once the shards hold this many episodes (sync mode, recording
            only). Each worker records at most its :attr:`episode_quotas` share; a lost
            worker's missing share is not made up by the others.
        batch_keys: keys of the batches the workers send back once recorded (recording only;
            default everything; ``()`` keeps the frames on the workers for a record-only run).
        **collector_kwargs: further arguments of each remote TorchRL collector.

    Attributes:
        nodes: the cluster address of the node each collector runs on, as Ray placed them.

    Example:
        >>> config = RayCollectionConfig(num_collectors=2, sessions_per_env=2, num_cpus=2)
        >>> with RayCollection(config, env_factory(EnvConfig(), config), policy,
        ...                    frames_per_batch=8, total_frames=16) as collection:
        ...     [batch.shape for batch in collection]  # doctest: +SKIP
        [torch.Size([2, 2, 2]), torch.Size([2, 2, 2])]
    """

    def __init__(
        self,
        config: RayCollectionConfig,
        create_env: Callable[[], EnvBase],
        policy: nn.Module | Callable[[TensorDictBase], TensorDictBase] | None,
        *,
        frames_per_batch: int,
        total_frames: int,
        policy_factory: Callable[[], Callable[[TensorDictBase], TensorDictBase]] | None = None,
        seed: int = 0,
        recorder_kwargs: dict[str, Any] | None = None,
        max_episodes: int | None = None,
        batch_keys: Sequence[NestedKey] | None = None,
        **collector_kwargs: Any,
    ) -> None:
        self.config = config
        self.total_frames = total_frames
        self.lost_workers: list[int] = []
        self.shard_episodes: dict[int, int] = {}
        self._recording = config.shard_root is not None
        self._check_recording_options(max_episodes, batch_keys)
        self.max_episodes = max_episodes
        self.episode_quotas = split_evenly(max_episodes or 0, config.num_collectors)
        self._recorded = dict.fromkeys(range(config.num_collectors), 0)
        self._owns_ray = not ray.is_initialized() and config.is_local
        if not ray.is_initialized():
            check_reachable(config.address, config.startup_timeout_s)
            ray.init(**config.init_kwargs())
        create_envs = [
            SeededEnvFactory(create_env, worker_seed)
            for worker_seed in worker_seeds(seed, config.num_collectors)
        ]
        self._group = None
        self.collector: RayCollector | None = None
        try:
            self._check_local_cpus()
            self._group = reserve_collectors(config)
            with warnings.catch_warnings():
                # Built in the workers, a factory's policy has no central weights to sync.
                warnings.filterwarnings("ignore", "The policy is not an nn.Module")
                self.collector = RayCollector(
                    create_envs,
                    policy,
                    policy_factory=policy_factory,
                    frames_per_batch=frames_per_batch,
                    total_frames=total_frames,
                    collector_class=(
                        Collector if config.envs_per_collector == 1 else MultiSyncCollector
                    ),
                    collector_kwargs=self._worker_kwargs(
                        collector_kwargs, recorder_kwargs or {}, batch_keys
                    ),
                    num_workers_per_collector=config.envs_per_collector,
                    num_collectors=config.num_collectors,
                    remote_configs=collector_options(config, self._group),
                    sync=config.sync,
                    weight_sync_schemes={}
                    if policy is None
                    else {"policy": ray_weight_sync_scheme()},
                )
            self.nodes = collector_nodes(self.collector.remote_collectors, config.startup_timeout_s)
            if isinstance(policy, nn.Module):
                self.collector.update_policy_weights_(policy)
        except RayActorError as error:  # raised by TorchRL's set-up calls to the actors
            self._release()
            raise ClusterStartupError(
                f"a collector was lost before it started (its node died?): "
                f"{str(error).splitlines()[0]}"
            ) from None
        except BaseException:
            self._release()
            raise
        self._workers = list(range(config.num_collectors))
        self._closed = False

    def _check_recording_options(
        self, max_episodes: int | None, batch_keys: Sequence[NestedKey] | None
    ) -> None:
        if (max_episodes is not None or batch_keys is not None) and not self._recording:
            raise ValueError("max_episodes and batch_keys need recording (ray.shard_root)")
        if max_episodes is not None and not self.config.sync:
            raise ValueError("max_episodes needs ray.sync=true (workers are polled between rounds)")
        if max_episodes is not None and max_episodes < 1:
            raise ValueError(f"max_episodes must be >= 1, got {max_episodes}")

    def _check_local_cpus(self) -> None:
        """A local runtime cannot grow: actors it has no CPUs for would wait forever."""
        if not self.config.is_local:
            return
        needed = self.config.num_collectors * self.config.cpus_per_collector
        available = ray.cluster_resources().get("CPU", 0.0)
        if needed > available:
            raise ValueError(
                f"{self.config.num_collectors} collectors x {self.config.cpus_per_collector} "
                f"CPUs need {needed:g} CPUs, the local Ray runtime has {available:g}; use fewer "
                "collectors, fewer cpus_per_collector or a cluster (address)"
            )

    def _worker_kwargs(
        self,
        collector_kwargs: dict[str, Any],
        recorder_kwargs: dict[str, Any],
        batch_keys: Sequence[NestedKey] | None,
    ) -> list[dict[str, Any]]:
        """One kwargs dict per remote collector (each with its own shard hook)."""
        per_worker = [dict(collector_kwargs) for _ in range(self.config.num_collectors)]
        if self._recording:
            for worker, kwargs in enumerate(per_worker):
                kwargs["post_collect_hook"] = ShardRecorder(
                    Path(self.config.shard_root).absolute(),  # workers on other nodes: other cwd
                    worker,
                    part_batches=self.config.part_batches,
                    max_episodes=None if self.max_episodes is None else self.episode_quotas[worker],
                    batch_keys=batch_keys,
                    **recorder_kwargs,
                )
        return per_worker

    @property
    def live_workers(self) -> list[int]:
        """Indices (as configured) of the collectors still running."""
        return list(self._workers)

    @property
    def recorded_episodes(self) -> int:
        """Episodes the shards held at the last poll (``max_episodes`` runs; lost workers count
        with their last poll, which includes their unfinished part)."""
        return sum(self._recorded.values())

    @property
    def shards_full(self) -> bool:
        """Whether every live worker has recorded its share of ``max_episodes``."""
        return self.max_episodes is not None and all(
            self._recorded[worker] >= self.episode_quotas[worker] for worker in self._workers
        )

    def update_policy_weights_(self, policy: nn.Module | TensorDictBase) -> None:
        """Send new weights to every live worker (TorchRL's Ray weight sync)."""
        self.collector.update_policy_weights_(policy)

    # -- iteration -----------------------------------------------------------------------

    def __iter__(self) -> Iterator[TensorDictBase]:
        """Yield batches until ``total_frames`` (or, with ``max_episodes``, full shards); a lost
        worker is handled per ``on_failure``."""
        while not self._closed and not self._finished():
            try:
                yield from self._batches()
            except RayActorError as error:
                self._on_worker_lost(error)

    def _finished(self) -> bool:
        return self.collector.collected_frames >= self.total_frames or self.shards_full

    def _batches(self) -> Iterator[TensorDictBase]:
        """TorchRL's iterator, left before it shuts the actors down so shards can finalize."""
        iterator = self.collector.iterator()
        try:
            for batch in iterator:
                self._poll_shards()
                yield batch
                if self._finished():
                    return
        finally:
            iterator.close()

    def _poll_shards(self) -> None:
        """Episodes recorded per live worker (asked between sync rounds: the actors are idle)."""
        if self.max_episodes is None:
            return
        counts = self.collector.get_distant_attr("post_collect_hook.episodes_written")
        self._recorded.update(zip(self._workers, counts, strict=True))

    def _on_worker_lost(self, error: RayActorError) -> None:
        lost = self._dead_workers()
        self.lost_workers.extend(lost)
        cause = str(error).strip().splitlines()
        logger.error("Ray collector worker(s) %s lost: %s", lost, cause[0] if cause else "")
        logger.debug("Ray's report of the loss: %s", error)
        self._drop(lost)
        if self.config.on_failure == "stop" or not self._workers:
            self.close()
            shards = "; the shards of the other workers are finalized" if self._recording else ""
            raise WorkerLostError(
                f"Ray collector worker(s) {lost} lost (on_failure={self.config.on_failure!r})"
                f"{shards}"
            ) from error
        logger.warning("continuing with workers %s", self._workers)

    def _dead_workers(self) -> list[int]:
        """Configured indices of the actors that no longer answer."""
        dead = []
        for worker, actor in zip(self._workers, self.collector.remote_collectors, strict=True):
            try:
                ray.get(actor.get_distant_attr.remote("frames_per_batch"), timeout=PING_TIMEOUT_S)
            except RayActorError:
                dead.append(worker)
        return dead

    def _drop(self, lost: list[int]) -> None:
        """Remove lost actors from the collector and its weight senders."""
        keep = [i for i, worker in enumerate(self._workers) if worker not in lost]
        drop_ray_collectors(self.collector, keep)
        self._workers = [self._workers[i] for i in keep]

    # -- closing -------------------------------------------------------------------------

    def close(self) -> dict[int, int]:
        """Finalize the live workers' shards, close their envs (every session finished), stop
        the actors (and a Ray runtime started here).

        Returns the episodes each live worker recorded (empty without recording).
        """
        if self._closed:
            return self.shard_episodes
        self._closed = True
        try:
            if self._recording and self._workers:
                episodes = self.collector.map_fn("post_collect_hook.close")
                self.shard_episodes = dict(zip(self._workers, episodes, strict=True))
        finally:
            self._close_envs()
            self._release()
        return self.shard_episodes

    def _close_envs(self) -> None:
        """Shut the live workers' collectors down (closing their envs), waiting a bounded time:
        Ray kills actors without closing anything."""
        closing = [actor.shutdown.remote() for actor in self.collector.remote_collectors]
        if not closing:
            return
        done, late = ray.wait(closing, num_returns=len(closing), timeout=CLOSE_TIMEOUT_S)
        for ref in done:
            with contextlib.suppress(RayActorError):  # lost since the last batch: nothing to close
                ray.get(ref)
        if late:
            logger.warning("%d workers did not close within %gs", len(late), CLOSE_TIMEOUT_S)

    def _release(self) -> None:
        """Stop the actors, free their reservation, stop a Ray runtime started here."""
        try:
            if self.collector is not None:
                self.collector.shutdown(shutdown_ray=False)
            if self._group is not None:
                remove_placement_group(self._group)
        finally:
            if self._owns_ray:
                ray.shutdown()
