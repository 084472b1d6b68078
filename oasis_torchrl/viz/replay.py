"""Replay saved data in rerun: ``.rrd`` recordings, saved rollouts and LeRobot datasets.

A *saved rollout* is the rollout TensorDict (``[N, T]``, as ``env.rollout`` and collectors return
it) in tensordict's memory-mapped format: :func:`save_rollout` writes it (``rollout.memmap``), a
folder with a ``meta.json``. Replaying maps it lazily, so a long rollout never has to fit in
memory. (``torch.save`` files are not read: unpickling runs arbitrary code.)
"""

from __future__ import annotations

import logging
import subprocess
import sys
from pathlib import Path

from tensordict import TensorDict, TensorDictBase

from oasis_torchrl.data.loading import is_dataset_root
from oasis_torchrl.viz.logger import RolloutLogger
from oasis_torchrl.viz.recording import DEFAULT_MEMORY_LIMIT

logger = logging.getLogger(__name__)

RRD, DATASET, ROLLOUT = "rrd", "dataset", "rollout"
_MEMMAP_META = "meta.json"


def source_kind(path: str | Path) -> str:
    """``"rrd"``, ``"dataset"`` (LeRobot) or ``"rollout"`` (saved rollout), else a ValueError.

    Example:
        >>> source_kind("missing.rrd")
        Traceback (most recent call last):
        ...
        ValueError: missing.rrd does not exist
    """
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path} does not exist")
    if path.is_file() and path.suffix == ".rrd":
        return RRD
    if path.is_dir() and is_dataset_root(path):
        return DATASET
    if path.is_dir() and (path / _MEMMAP_META).is_file():
        return ROLLOUT
    raise ValueError(
        f"{path} is neither an .rrd file, a LeRobot dataset folder (meta/info.json) nor a saved "
        f"rollout folder ({_MEMMAP_META}, written by save_rollout)"
    )


def save_rollout(rollout: TensorDictBase, path: str | Path) -> Path:
    """Save a rollout ``[N, T]`` for ``oasis-torchrl view`` (memory-mapped tensordict folder).

    Example:
        >>> import tempfile, torch
        >>> rollout = TensorDict({"reward": torch.zeros(2, 3, 1)}, [2, 3])
        >>> folder = save_rollout(rollout, f"{tempfile.mkdtemp()}/run")
        >>> load_rollout(folder).batch_size
        torch.Size([2, 3])
    """
    if rollout.batch_dims != 2:
        raise ValueError(
            f"a rollout must have batch size [N, T] (time last), got {list(rollout.batch_size)}"
        )
    path = Path(path)
    if path.exists() and any(path.iterdir()):
        raise FileExistsError(f"{path} exists and is not empty; choose a new folder")
    rollout.memmap(path)
    return path


def load_rollout(path: str | Path) -> TensorDictBase:
    """A rollout saved by :func:`save_rollout`, memory-mapped (nothing is read until used).

    Example:
        >>> import tempfile, torch
        >>> rollout = TensorDict({"reward": torch.ones(1, 2, 1)}, [1, 2])
        >>> folder = save_rollout(rollout, f"{tempfile.mkdtemp()}/run")
        >>> load_rollout(folder)["reward"].sum().item()
        2.0
    """
    if source_kind(path) != ROLLOUT:
        raise ValueError(f"{path} is not a saved rollout folder")
    return TensorDict.load_memmap(path)


def replay_rollout(path: str | Path, rollout_logger: RolloutLogger) -> None:
    """Log a saved rollout with ``rollout_logger`` (every row starts an episode at ``t = 0``).

    Example:
        >>> import tempfile, torch
        >>> rollout = TensorDict({("next", "reward"): torch.ones(1, 2, 1)}, [1, 2])
        >>> folder = save_rollout(rollout, f"{tempfile.mkdtemp()}/run")
        >>> with RolloutLogger(f"{folder}.rrd") as rerun_logger:
        ...     replay_rollout(folder, rerun_logger)
    """
    rollout_logger.log_rollout(load_rollout(path))


def viewer_command(rrd: str | Path, memory_limit: str = DEFAULT_MEMORY_LIMIT) -> list[str]:
    """The command that opens ``rrd`` in the native viewer of the installed rerun-sdk.

    Example:
        >>> viewer_command("run.rrd", "2GB")[-3:]
        ['run.rrd', '--memory-limit', '2GB']
    """
    return [sys.executable, "-m", "rerun", str(rrd), "--memory-limit", memory_limit]


def open_in_viewer(rrd: str | Path, memory_limit: str = DEFAULT_MEMORY_LIMIT) -> subprocess.Popen:
    """Open ``rrd`` in a native viewer process that outlives this one (needs a display).

    Example:
        >>> viewer = open_in_viewer("run.rrd", "2GB")  # doctest: +SKIP
    """
    if source_kind(rrd) != RRD:
        raise ValueError(f"{rrd} is not an .rrd file")
    logger.info("opening %s in the rerun viewer", rrd)
    return subprocess.Popen(viewer_command(rrd, memory_limit), start_new_session=True)
