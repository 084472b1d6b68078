"""Keeping the dataset libraries' chatter out of the project's progress bars."""

from __future__ import annotations

import logging
import os
import warnings


def _not_lerobot_chatter(record: logging.LogRecord) -> bool:
    # LeRobot logs through the root logger, so its INFO lines can only be told by their file.
    return record.levelno >= logging.WARNING or f"{os.sep}lerobot{os.sep}" not in record.pathname


def quiet_dataset_libraries() -> None:
    """Keep LeRobot's and ``datasets``' per-episode chatter and bars out of our progress bar.

    Example:
        >>> quiet_dataset_libraries()
    """
    import datasets

    datasets.disable_progress_bars()
    for handler in logging.getLogger().handlers:
        handler.addFilter(_not_lerobot_chatter)
    warnings.filterwarnings("ignore", message="Converting input from bool", category=RuntimeWarning)
