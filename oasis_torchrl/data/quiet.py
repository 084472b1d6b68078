"""Keeping the dataset libraries' chatter out of the project's progress bars."""

from __future__ import annotations

import logging
import os
import warnings


def _not_lerobot_chatter(record: logging.LogRecord) -> bool:
    # LeRobot logs through the root logger, so its INFO lines can only be told by their file.
    return record.levelno >= logging.WARNING or f"{os.sep}lerobot{os.sep}" not in record.pathname


_quiet = False


def quiet_dataset_libraries() -> None:
    """Keep LeRobot's and ``datasets``' per-episode chatter and bars out of our progress bar.

    Example:
        >>> quiet_dataset_libraries()
    """
    import datasets

    global _quiet
    _quiet = True
    datasets.disable_progress_bars()
    for handler in logging.getLogger().handlers:
        handler.addFilter(_not_lerobot_chatter)
    warnings.filterwarnings("ignore", message="Converting input from bool", category=RuntimeWarning)


def keep_dataset_libraries_quiet() -> None:
    """Turn the bars of ``datasets`` off again if :func:`quiet_dataset_libraries` asked for it.

    LeRobot turns them on whenever it has loaded a dataset's tables (its ``SuppressProgressBars``
    enables them on exit, whatever they were before), which it also does while saving an
    episode; the dataset writer calls this before each save.

    Example:
        >>> keep_dataset_libraries_quiet()
    """
    if _quiet:
        import datasets

        datasets.disable_progress_bars()
