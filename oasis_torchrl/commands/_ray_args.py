"""Flags of the ``--ray`` switch of a dataset-writing command (``record``): where Ray runs, how
wide, where the shards go, what a lost worker does."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from oasis_torchrl.distributed import RayCollectionConfig

RAY_FLAGS = {
    "ray_address": "--ray-address",
    "collectors": "--collectors",
    "sessions_per_env": "--sessions-per-env",
    "cpus_per_collector": "--cpus-per-collector",
    "server_address": "--server-address",
    "shard_root": "--shard-root",
    "batch_steps": "--batch-steps",
    "part_batches": "--part-batches",
    "on_failure": "--on-failure",
    "keep_shards": "--keep-shards",
}
"""Destination -> flag of the options that only mean something with ``--ray``."""
DEFAULT_BATCH_STEPS = 8


def add_ray_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``--ray`` switch and its options (all None unless given, so misuse can be named).

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_ray_arguments(parser)
        >>> parser.parse_args(["--ray", "--collectors", "4"]).collectors
        4
    """
    group = parser.add_argument_group("Ray (record on Ray workers, then merge)")
    group.add_argument("--ray", action="store_true", help="record on Ray workers, then merge")
    group.add_argument(
        "--ray-address",
        help="Ray cluster to join (auto, host:6379, ray://host:10001; default: a local runtime)",
    )
    group.add_argument("--collectors", type=int, help="Ray workers (2)")
    group.add_argument("--sessions-per-env", type=int, help="sessions of each worker (4)")
    group.add_argument("--cpus-per-collector", type=float, help="Ray CPUs per worker (1)")
    group.add_argument(
        "--server-address",
        help="one shared A2V server (http://host:port of 'oasis-torchrl serve') for all "
        "workers (default: an embedded server in each worker)",
    )
    group.add_argument(
        "--shard-root",
        type=Path,
        help="where the workers write their shards; must be empty, shared by all nodes on a "
        "cluster (default: <root>.shards beside the dataset)",
    )
    group.add_argument(
        "--batch-steps",
        type=int,
        help=f"env steps per session between worker reports ({DEFAULT_BATCH_STEPS})",
    )
    group.add_argument(
        "--part-batches",
        type=int,
        help="finalize a shard part every N batches, so a lost worker loses at most one part; "
        "an episode running at a part's end is stored as two (0: one part per worker)",
    )
    group.add_argument(
        "--on-failure",
        choices=("stop", "continue"),
        help="a lost worker stops the run (stop, default) or the others carry on (continue)",
    )
    group.add_argument(
        "--keep-shards", action="store_true", help="keep the shards after merging them"
    )


def check_ray_flags(args: argparse.Namespace) -> None:
    """Refuse Ray options given without ``--ray``, naming them.

    Example:
        >>> check_ray_flags(argparse.Namespace(ray=False, collectors=4))
        Traceback (most recent call last):
        ...
        ValueError: Ray options without --ray: --collectors
    """
    given = [
        flag for dest, flag in RAY_FLAGS.items() if getattr(args, dest, None) not in (None, False)
    ]
    if given and not args.ray:
        raise ValueError(f"Ray options without --ray: {', '.join(given)}")


def ray_config(args: argparse.Namespace, root: Path) -> RayCollectionConfig:
    """The Ray settings the flags ask for (``RayCollectionConfig`` defaults for the others);
    the shards go beside the dataset ``root`` unless ``--shard-root`` says where.

    Example:
        >>> parser = argparse.ArgumentParser()
        >>> add_ray_arguments(parser)
        >>> args = parser.parse_args(["--ray", "--collectors", "4"])
        >>> config = ray_config(args, root=Path("drives"))
        >>> config.num_collectors, config.shard_root
        (4, 'drives.shards')
    """
    from oasis_torchrl.distributed import RayCollectionConfig

    given = {
        "address": args.ray_address,
        "num_collectors": args.collectors,
        "sessions_per_env": args.sessions_per_env,
        "cpus_per_collector": args.cpus_per_collector,
        "server_address": args.server_address,
        "part_batches": args.part_batches,
        "on_failure": args.on_failure,
    }
    shard_root = args.shard_root or root.with_name(f"{root.name}.shards")
    return RayCollectionConfig(
        enabled=True,
        shard_root=str(shard_root),
        **{key: value for key, value in given.items() if value is not None},
    )
