"""``oasis-torchrl import-recordings``: human driving recordings into a LeRobot dataset.

Reads the reference SDK's layout (``<source>/episode_<id>/manifest.jsonl`` plus PNG frames);
each bad episode is reported with its file and line and skipped, the others are imported.
"""

from __future__ import annotations

import logging

from omegaconf import DictConfig

from oasis_torchrl.commands._signals import sigterm_as_interrupt
from oasis_torchrl.config.recording import ImportConfig

logger = logging.getLogger(__name__)

NAME = "import-recordings"
HELP = "import human driving recordings (episode_*/manifest.jsonl + PNGs) as a LeRobot dataset"
CONFIG = ImportConfig


def run(cfg: DictConfig) -> int:
    """Import; exit code 0 (all imported), 1 (some skipped), 2 (nothing imported or bad flags),
    130 when interrupted (SIGINT or SIGTERM; the episodes imported so far are kept).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("import-recordings", ["source=/nowhere", "root=/tmp/never"]))
        2
    """
    from tqdm import tqdm

    from oasis_torchrl.data import import_recordings
    from oasis_torchrl.data.importer import find_episodes
    from oasis_torchrl.data.quiet import quiet_dataset_libraries

    quiet_dataset_libraries()
    try:
        total = len(find_episodes(cfg.source))
        with sigterm_as_interrupt(), tqdm(total=total, unit="episode", desc="importing") as bar:
            report = import_recordings(
                cfg.source,
                cfg.root,
                repo_id=cfg.repo_id,
                task=cfg.task,
                fps=cfg.fps,
                drop_idle=cfg.drop_idle,
                source_size=tuple(cfg.source_size),
                image_size=None if cfg.image_size is None else tuple(cfg.image_size),
                vcodec=cfg.vcodec,
                crf=cfg.crf,
                append=cfg.append,
                on_episode=lambda episode, rows: bar.update(1),
            )
    except (ValueError, FileExistsError, FileNotFoundError) as error:
        logger.error("cannot import: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted; %s keeps every episode imported so far", cfg.root)
        return 130
    for error in report.skipped:
        logger.warning("skipped: %s", error)
    logger.info(
        "imported %d episodes (%d rows) into %s, skipped %d",
        len(report.imported),
        report.rows,
        cfg.root,
        len(report.skipped),
    )
    if not report.imported:
        return 2
    return 1 if report.skipped else 0
