"""Settings of Ray collection (the ``ray`` section of ``configs/ray.yaml``).

Keys: ``enabled``, ``address`` (``local`` starts a Ray runtime in this process; ``auto``, a
``host:port`` or a ``ray://host:10001`` address joins an existing cluster), ``num_collectors``
(Ray actors), ``envs_per_collector``, ``sessions_per_env`` (rows of each ``OasisEnv``),
``server_address`` (``null``: every env starts its own embedded server; an ``http://host:port``
of an ``oasis-torchrl serve`` server: all envs share it), ``cpus_per_collector``, ``num_cpus``
and ``object_store_memory`` (local runtime only), ``sync`` (one batch from every collector per
iteration, or first-ready), ``on_failure`` (``stop`` or ``continue``), ``shard_root`` (record
each worker's batches into its own LeRobot shard there) and ``part_batches`` (close and start a
new shard part every that many batches, so a killed worker loses at most one part; 0: never).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from omegaconf import DictConfig, OmegaConf

LOCAL_ADDRESS = "local"
FAILURE_POLICIES = ("stop", "continue")


@dataclass(frozen=True)
class RayCollectionConfig:
    """Where and how wide Ray collection runs; see the module docstring for each field.

    Example:
        >>> cfg = RayCollectionConfig(num_collectors=2, sessions_per_env=3)
        >>> cfg.total_sessions
        6
        >>> cfg.init_kwargs()["address"]
        'local'
    """

    enabled: bool = False
    address: str = LOCAL_ADDRESS
    num_collectors: int = 2
    envs_per_collector: int = 1
    sessions_per_env: int = 4
    server_address: str | None = None
    cpus_per_collector: float = 1.0
    num_cpus: int | None = None
    object_store_memory: int | None = None
    sync: bool = True
    on_failure: str = "stop"
    shard_root: str | None = None
    part_batches: int = 0

    def __post_init__(self) -> None:
        for name in ("num_collectors", "envs_per_collector", "sessions_per_env"):
            if getattr(self, name) < 1:
                raise ValueError(f"ray.{name} must be >= 1, got {getattr(self, name)}")
        if self.on_failure not in FAILURE_POLICIES:
            raise ValueError(
                f"ray.on_failure must be one of {FAILURE_POLICIES}, got {self.on_failure!r}"
            )
        if self.part_batches < 0:
            raise ValueError(f"ray.part_batches must be >= 0, got {self.part_batches}")
        if self.shard_root is not None and self.envs_per_collector != 1:
            # The hook would run in each env's subprocess, all writing the same shard.
            raise ValueError(
                f"ray.shard_root needs ray.envs_per_collector=1, got {self.envs_per_collector}; "
                "widen with sessions_per_env or num_collectors instead"
            )

    @classmethod
    def from_config(cls, section: DictConfig | dict[str, Any]) -> RayCollectionConfig:
        """Build from a config section; unknown keys are an error naming them.

        Example:
            >>> RayCollectionConfig.from_config({"num_collectors": 3}).num_collectors
            3
        """
        values = (
            OmegaConf.to_container(section, resolve=True)
            if isinstance(section, DictConfig)
            else dict(section)
        )
        known = {field.name for field in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown ray config keys {unknown}; known: {sorted(known)}")
        return cls(**values)

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
        """Ray resources of one collector actor.

        Example:
            >>> RayCollectionConfig(cpus_per_collector=0.5).remote_config()
            {'num_cpus': 0.5, 'num_gpus': 0}
        """
        return {"num_cpus": self.cpus_per_collector, "num_gpus": 0}
