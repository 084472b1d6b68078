"""Reaching a Ray cluster and placing the collectors on it, failing fast and by name.

Ray waits without a word for a cluster it cannot reach and for actors no node can host; a run
instead stops within ``ray.startup_timeout_s`` with one line naming what it asked for and what
the cluster has. Collectors are reserved as one placement group (one bundle each, spread over
the nodes), so a cluster that cannot host all of them is known before any actor starts.
"""

from __future__ import annotations

import ipaddress
import logging
import socket
import time
from collections.abc import Sequence
from typing import Any
from urllib.parse import urlsplit

import ray
from ray.exceptions import GetTimeoutError, RayActorError
from ray.util.placement_group import PlacementGroup, placement_group, remove_placement_group
from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

from oasis_torchrl.config.ray import RayCollectionConfig

logger = logging.getLogger(__name__)


class ClusterStartupError(ValueError):
    """The Ray cluster cannot start the run as configured (unreachable, or short of what the
    collectors ask for, or a node lost before its collector started)."""


def cluster_endpoint(address: str) -> tuple[str, int] | None:
    """The ``(host, port)`` a cluster address connects to; None for ``local`` and ``auto``.

    Example:
        >>> cluster_endpoint("10.77.0.1:6379"), cluster_endpoint("ray://head:10001")
        (('10.77.0.1', 6379), ('head', 10001))
        >>> cluster_endpoint("auto") is None
        True
    """
    if address in ("local", "auto"):
        return None
    parts = urlsplit(address if "://" in address else f"//{address}")
    if parts.hostname is None or parts.port is None:
        raise ClusterStartupError(f"ray.address {address!r} is not host:port or ray://host:port")
    return parts.hostname, parts.port


def check_reachable(address: str, timeout: float) -> None:
    """Raise :class:`ClusterStartupError` unless a TCP connection to ``address`` opens within
    ``timeout`` seconds (Ray itself would retry for minutes).

    Example:
        >>> check_reachable("127.0.0.1:1", timeout=1.0)
        Traceback (most recent call last):
        ...
        oasis_torchrl.distributed.placement.ClusterStartupError: cannot reach the Ray cluster at 127.0.0.1:1 within 1s: [Errno 111] Connection refused
    """  # noqa: E501
    endpoint = cluster_endpoint(address)
    if endpoint is None:
        return
    try:
        socket.create_connection(endpoint, timeout=timeout).close()
    except OSError as error:
        raise ClusterStartupError(
            f"cannot reach the Ray cluster at {address} within {timeout:g}s: {error}"
        ) from None


def describe_cluster() -> str:
    """The alive nodes of the connected cluster and their resources, in one line.

    Example:
        >>> describe_cluster()  # doctest: +SKIP
        '2 alive nodes: 10.77.0.1 {CPU: 1, memory: 2.1e+09}, 10.77.0.2 {CPU: 1, memory: 2.0e+09}'
    """
    nodes = sorted(
        (node for node in ray.nodes() if node["Alive"]),
        key=lambda node: _address_order(node["NodeManagerAddress"]),
    )
    shown = [f"{node['NodeManagerAddress']} {_resources(node['Resources'])}" for node in nodes]
    return f"{len(nodes)} alive node{'s' * (len(nodes) != 1)}: " + ", ".join(shown)


def _address_order(address: str) -> tuple[int, int, str]:
    """Sort key of a node's address: IP addresses in numeric order, then host names.

    Example:
        >>> sorted(["10.77.0.10", "host", "10.77.0.2"], key=_address_order)
        ['10.77.0.2', '10.77.0.10', 'host']
    """
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        return (99, 0, address)
    return (ip.version, int(ip), address)


def _resources(resources: dict[str, float]) -> str:
    """Resources without Ray's per-node bookkeeping entries (``node:...``, ``object_store...``)."""
    schedulable = {
        name: amount
        for name, amount in resources.items()
        if not name.startswith("node:") and name != "object_store_memory"
    }
    return (
        "{" + ", ".join(f"{name}: {amount:g}" for name, amount in sorted(schedulable.items())) + "}"
    )


def reserve_collectors(config: RayCollectionConfig) -> PlacementGroup:
    """Reserve one bundle per collector (spread over the nodes) within the start-up timeout.

    Raises:
        ClusterStartupError: naming the request and the cluster's nodes, after removing the
            unfulfilled reservation.
    """
    bundle = config.bundle()
    group = placement_group([bundle] * config.num_collectors, strategy="SPREAD")
    try:
        ray.get(group.ready(), timeout=config.startup_timeout_s)
    except GetTimeoutError:
        remove_placement_group(group)
        raise ClusterStartupError(
            f"the Ray cluster could not place {config.num_collectors} collectors x "
            f"{_resources(bundle)} within {config.startup_timeout_s:g}s (ray.startup_timeout_s); "
            f"it has {describe_cluster()}"
        ) from None
    return group


def collector_options(config: RayCollectionConfig, group: PlacementGroup) -> list[dict[str, Any]]:
    """``ray.remote`` options of each collector: its resources, in its bundle of ``group``."""
    return [
        {
            **config.remote_config(),
            "scheduling_strategy": PlacementGroupSchedulingStrategy(
                placement_group=group, placement_group_bundle_index=index
            ),
        }
        for index in range(config.num_collectors)
    ]


def _node_address(_actor: Any) -> str:
    return ray.util.get_node_ip_address()


def collector_nodes(actors: Sequence[Any], timeout: float) -> list[str]:
    """The cluster address of the node each started actor runs on (asked of the actors).

    Raises:
        ClusterStartupError: an actor died before it started (its node lost) or did not
            start within ``timeout`` seconds.
    """
    started = time.monotonic()
    asked = [actor.__ray_call__.remote(_node_address) for actor in actors]
    ready, _ = ray.wait(asked, num_returns=len(asked), timeout=timeout)
    late = [index for index, ref in enumerate(asked) if ref not in ready]
    if late:
        raise ClusterStartupError(
            f"collectors {late} did not start within {timeout:g}s (ray.startup_timeout_s); "
            f"the cluster has {describe_cluster()}"
        )
    nodes = []
    for index, ref in enumerate(asked):
        try:
            nodes.append(ray.get(ref))
        except RayActorError as error:
            raise ClusterStartupError(
                f"collector {index} was lost before it started (its node died?): "
                f"{str(error).splitlines()[0]}; the cluster has {describe_cluster()}"
            ) from None
    logger.info(
        "collectors placed in %.1fs: %s",
        time.monotonic() - started,
        ", ".join(f"{index} on {node}" for index, node in enumerate(nodes)),
    )
    return nodes
