"""Combine finalized LeRobot datasets into a new one, written whole or not at all.

The combining is lerobot's own ``aggregate_datasets``: episode indices renumbered in the given
order, tasks unified, videos and parquet files concatenated (not re-encoded), statistics
aggregated. The sources are only read.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from oasis_torchrl.atomic import written_whole
from oasis_torchrl.data.loading import dataset_repo_id, default_repo_id

logger = logging.getLogger(__name__)


def combine_datasets(
    roots: Sequence[str | Path], output: str | Path, *, repo_id: str | None = None
) -> Path:
    """Write the episodes of every dataset in ``roots``, in order, into a new dataset at
    ``output``; it appears only once complete.

    Args:
        roots: finalized LeRobot dataset folders of one layout (fps, features).
        output: the combined dataset's folder (must not exist).
        repo_id: LeRobot repo id of the result (default ``local/<output folder name>``).

    Raises:
        FileExistsError: ``output`` exists.
        FileNotFoundError: a root holds no LeRobot dataset (named).
        ValueError: no roots.

    Example:
        >>> combine_datasets(["demos", "bc/round_1/dagger"], "bc/round_1/dataset")  # doctest: +SKIP
        PosixPath('bc/round_1/dataset')
    """
    from lerobot.datasets.aggregate import aggregate_datasets

    output = Path(output)
    if output.exists():
        raise FileExistsError(f"{output} already exists: the combined dataset is written anew")
    if not roots:
        raise ValueError("no datasets to combine")
    repo_ids = [dataset_repo_id(root) for root in roots]  # names a folder that holds none
    with written_whole(output) as partial:
        aggregate_datasets(
            repo_ids=repo_ids,
            aggr_repo_id=repo_id or default_repo_id(output),
            roots=[Path(root) for root in roots],
            aggr_root=partial,
        )
    logger.info("combined %d datasets into %s", len(roots), output)
    return output
