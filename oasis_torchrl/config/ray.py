"""Settings of Ray collection: the ``ray`` section of the PPO config and of ``record --ray``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from oasis_torchrl.options import Alias, option

LOCAL_ADDRESS = "local"
FAILURE_POLICIES = ("stop", "continue")
RAY_ALIASES = {
    "--ray": Alias("ray.enabled"),
    "--ray-address": Alias("ray.address"),
    "--collectors": Alias("ray.num_collectors"),
    "--sessions-per-env": Alias("ray.sessions_per_env"),
    "--cpus-per-collector": Alias("ray.cpus_per_collector"),
    "--server-address": Alias("ray.server_address"),
    "--shard-root": Alias("ray.shard_root"),
    "--part-batches": Alias("ray.part_batches"),
    "--on-failure": Alias("ray.on_failure"),
}
"""Short flags of the ``ray`` section of a command that records or collects on Ray."""


def parse_resources(entries: list[str]) -> dict[str, float]:
    """Ray's resource dict of ``name=amount`` entries.

    Example:
        >>> parse_resources(["gpu_box=1"])
        {'gpu_box': 1.0}
        >>> parse_resources(["gpu_box"])
        Traceback (most recent call last):
        ...
        ValueError: ray.resources_per_collector entries are name=amount, got 'gpu_box'
    """
    resources = {}
    for entry in entries:
        name, _, amount = entry.partition("=")
        try:
            resources[name.strip()] = float(amount)
        except ValueError:
            raise ValueError(
                f"ray.resources_per_collector entries are name=amount, got {entry!r}"
            ) from None
    return resources


@dataclass(frozen=True)
class RayCollectionConfig:
    """Where and how wide Ray collection runs (each field's help says what it sets).

    Example:
        >>> cfg = RayCollectionConfig(num_collectors=2, sessions_per_env=3)
        >>> cfg.total_sessions
        6
        >>> cfg.init_kwargs()["address"]
        'local'
    """

    enabled: bool = option(False, help="collect on Ray instead of in this process")
    address: str = option(
        LOCAL_ADDRESS,
        help="local (start a Ray runtime here) | auto | host:6379 | ray://host:10001",
    )
    num_collectors: int = option(2, help="Ray actors, each a TorchRL collector", ge=1)
    envs_per_collector: int = option(
        1, help="OasisEnvs per actor (> 1: a MultiSyncCollector inside the actor)", ge=1
    )
    sessions_per_env: int = option(4, help="world-model sessions (rows) of each OasisEnv", ge=1)
    server_address: str | None = option(
        None,
        help="null: an embedded server per env; http://host:port of an 'oasis-torchrl serve' "
        "server: all envs share it",
    )
    cpus_per_collector: float = option(1.0, help="Ray CPUs reserved per actor")
    memory_per_collector: int | None = option(
        None, help="bytes of Ray memory reserved per actor (null: none reserved)"
    )
    resources_per_collector: list[str] = option(
        default_factory=list,
        help="custom Ray resources reserved per actor, as name=amount, e.g. [gpu_box=1] (nodes "
        "started with ray start --resources)",
    )
    startup_timeout_s: float = option(
        120.0,
        help="seconds to reach the cluster and place every actor before the run stops, naming "
        "what was asked and what the cluster has",
        gt=0.0,
    )
    num_cpus: int | None = option(None, help="local runtime only: CPUs Ray may use (null: all)")
    object_store_memory: int | None = option(
        None, help="local runtime only: bytes of object store (null: Ray's default)"
    )
    sync: bool = option(True, help="one batch from every actor per iteration; false: first-ready")
    on_failure: str = option(
        "stop",
        help="a lost actor: stop (finalize shards, raise) | continue without it",
        choices=FAILURE_POLICIES,
    )
    shard_root: str | None = option(
        None, help="record each actor's batches as a LeRobot shard under this folder"
    )
    part_batches: int = option(
        0,
        help="finalize a new shard part every N batches, so a lost worker loses at most one "
        "part (0: once, at the end)",
        ge=0,
    )

    def __post_init__(self) -> None:
        parse_resources(self.resources_per_collector)  # a malformed entry raises here
        if self.shard_root is not None and self.envs_per_collector != 1:
            # The hook would run in each env's subprocess, all writing the same shard.
            raise ValueError(
                f"ray.shard_root needs ray.envs_per_collector=1, got {self.envs_per_collector}; "
                "widen with sessions_per_env or num_collectors instead"
            )

    @property
    def custom_resources(self) -> dict[str, float]:
        """``resources_per_collector`` as Ray's resource dict (see :func:`parse_resources`)."""
        return parse_resources(self.resources_per_collector)

    @property
    def total_sessions(self) -> int:
        """World-model sessions over all collectors."""
        return self.num_collectors * self.envs_per_collector * self.sessions_per_env

    @property
    def is_local(self) -> bool:
        """Whether a Ray runtime is started here rather than joined."""
        return self.address == LOCAL_ADDRESS

    def init_kwargs(self) -> dict[str, Any]:
        """Arguments of ``ray.init`` for this config.

        Example:
            >>> RayCollectionConfig(address="auto").init_kwargs()
            {'address': 'auto'}
        """
        if not self.is_local:
            return {"address": self.address}
        kwargs: dict[str, Any] = {"address": LOCAL_ADDRESS, "include_dashboard": False}
        if self.num_cpus is not None:
            kwargs["num_cpus"] = self.num_cpus
        if self.object_store_memory is not None:
            kwargs["object_store_memory"] = self.object_store_memory
        return kwargs

    def remote_config(self) -> dict[str, Any]:
        """Ray resources of one collector actor (``ray.remote`` options).

        Example:
            >>> RayCollectionConfig(cpus_per_collector=0.5).remote_config()
            {'num_cpus': 0.5, 'num_gpus': 0}
            >>> RayCollectionConfig(memory_per_collector=2**30, resources_per_collector=["box=1"]
            ...                     ).remote_config()
            {'num_cpus': 1.0, 'num_gpus': 0, 'memory': 1073741824, 'resources': {'box': 1.0}}
        """
        options: dict[str, Any] = {"num_cpus": self.cpus_per_collector, "num_gpus": 0}
        if self.memory_per_collector is not None:
            options["memory"] = self.memory_per_collector
        if self.custom_resources:
            options["resources"] = self.custom_resources
        return options

    def bundle(self) -> dict[str, float]:
        """The resources of one collector as a Ray placement-group bundle.

        Example:
            >>> RayCollectionConfig(memory_per_collector=100, resources_per_collector=["box=1"]
            ...                     ).bundle()
            {'CPU': 1.0, 'memory': 100, 'box': 1.0}
        """
        bundle = {"CPU": self.cpus_per_collector, "memory": self.memory_per_collector}
        bundle.update(self.custom_resources)
        return {name: amount for name, amount in bundle.items() if amount}
