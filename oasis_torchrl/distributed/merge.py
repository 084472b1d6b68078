"""Merge the finalized shard parts of a sharded recording into one LeRobot dataset.

The merge is :func:`~oasis_torchrl.data.combine.combine_datasets` in shard order.
A part appears under its own name only once finalized; the hidden partial of a part a worker was
killed in is skipped and named in the log.
"""

from __future__ import annotations

import logging
from pathlib import Path

from oasis_torchrl.atomic import is_partial
from oasis_torchrl.data.combine import combine_datasets

logger = logging.getLogger(__name__)


def complete_shards(root: str | Path) -> list[Path]:
    """The finalized shard parts under ``root``, in name (worker, then part) order.

    Example:
        >>> import tempfile
        >>> complete_shards(tempfile.mkdtemp())
        []
    """
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"shard root {root} does not exist")
    folders = sorted(path for path in root.iterdir() if path.is_dir())
    unfinished = [path.name for path in folders if is_partial(path)]
    if unfinished:
        logger.warning("skipping unfinished shard parts (worker lost mid-part): %s", unfinished)
    # other hidden folders are a killed recorder's scratch, never a part
    return [path for path in folders if not path.name.startswith(".")]


def merge_shards(root: str | Path, output: str | Path, *, repo_id: str | None = None) -> Path:
    """Aggregate every finalized part under ``root`` into a new dataset at ``output``.

    Args:
        root: the sharded recording (``ray.shard_root``).
        output: the merged dataset folder (must not exist).
        repo_id: LeRobot repo id of the result (default ``local/<output folder name>``).

    Example:
        >>> merge_shards("recordings/shards", "recordings/drives")  # doctest: +SKIP
        PosixPath('recordings/drives')
    """
    shards = complete_shards(root)
    if not shards:
        raise ValueError(f"no finalized shard parts under {root}")
    output = combine_datasets(shards, output, repo_id=repo_id)
    logger.info("merged %d shard parts of %s into %s", len(shards), root, output)
    return output
