"""The main job's stage timing: each stage's wall time (:func:`timed_stage`), and a run
folder's total per stage over every run of it (:data:`STAGE_SECONDS`): the main job adds each
stage's time when the stage ends or stops; a shipped clone's card reads the totals.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

logger = logging.getLogger(__name__)

STAGE_SECONDS = "stage_seconds.json"
"""A run folder's wall time per stage over every run of it (a run stopped half way and the run
that finishes it both count; a reused stage adds nothing): what a shipped clone took to train."""


def add_stage_seconds(totals: Path, stage: str, elapsed: float) -> dict[str, float]:
    """Add ``elapsed`` seconds to ``stage``'s total in the JSON file ``totals``; the totals.

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / STAGE_SECONDS
        >>> add_stage_seconds(path, "bc", 60.0) and add_stage_seconds(path, "bc", 30.5)
        {'bc': 90.5}
    """
    seconds = json.loads(totals.read_text()) if totals.exists() else {}
    seconds[stage] = round(seconds.get(stage, 0.0) + elapsed, 1)
    totals.write_text(json.dumps(seconds, indent=2))
    return seconds


@contextmanager
def timed_stage(
    seconds: dict[str, float], stage: str, totals: Path | None = None
) -> Iterator[None]:
    """Log the start of ``stage`` and put its wall time (seconds, 0.1 s) in ``seconds``; with
    ``totals`` (a JSON file), also add it to the stage's total there, even if the stage stops
    half way.

    Example:
        >>> seconds = {}
        >>> with timed_stage(seconds, "record"):
        ...     pass
        >>> list(seconds)
        ['record']
    """
    logger.info("pipeline stage %s", stage)
    started = time.perf_counter()
    try:
        yield
    finally:
        elapsed = round(time.perf_counter() - started, 1)
        seconds[stage] = elapsed
        if totals is not None:
            add_stage_seconds(totals, stage, elapsed)
