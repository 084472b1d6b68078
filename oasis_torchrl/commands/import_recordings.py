"""``oasis-torchrl import-recordings``: human driving recordings into a LeRobot dataset.

Reads the reference SDK's layout (``<source>/episode_<id>/manifest.jsonl`` plus PNG frames);
each bad episode is reported with its file and line and skipped, the others are imported.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from oasis_torchrl.commands._dataset_args import (
    add_dataset_arguments,
    parse_size,
    quiet_dataset_libraries,
    sigterm_as_interrupt,
)

logger = logging.getLogger(__name__)

NAME = "import-recordings"
HELP = "import human driving recordings (episode_*/manifest.jsonl + PNGs) as a LeRobot dataset"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags: the recordings folder, the dataset to write, and how to read the recordings."""
    parser.add_argument("source", type=Path, help="folder holding episode_*/ recordings")
    add_dataset_arguments(parser)
    parser.add_argument("--task", default="human driving", help="task of every episode")
    parser.add_argument(
        "--drop-idle", action="store_true", help="drop each episode's leading all-zero chunks"
    )
    parser.add_argument(
        "--source-size",
        type=parse_size,
        default=(512, 768),
        metavar="HxW",
        help="frame size of the recordings (default 512x768)",
    )
    parser.add_argument("--fps", type=int, default=20, help="world-model frame rate (20)")


def run(args: argparse.Namespace) -> int:
    """Import; exit code 0 (all imported), 1 (some skipped), 2 (nothing imported or bad flags),
    130 when interrupted (SIGINT or SIGTERM; the episodes imported so far are kept)."""
    from tqdm import tqdm

    from oasis_torchrl.data import import_recordings
    from oasis_torchrl.data.importer import find_episodes

    quiet_dataset_libraries()
    try:
        total = len(find_episodes(args.source))
        with sigterm_as_interrupt(), tqdm(total=total, unit="episode", desc="importing") as bar:
            report = import_recordings(
                args.source,
                args.root,
                repo_id=args.repo_id,
                task=args.task,
                fps=args.fps,
                drop_idle=args.drop_idle,
                source_size=args.source_size,
                image_size=args.image_size,
                vcodec=args.vcodec,
                append=args.append,
                on_episode=lambda episode, rows: bar.update(1),
            )
    except (ValueError, FileExistsError, FileNotFoundError) as error:
        logger.error("cannot import: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted; %s keeps every episode imported so far", args.root)
        return 130
    for error in report.skipped:
        logger.warning("skipped: %s", error)
    logger.info(
        "imported %d episodes (%d rows) into %s, skipped %d",
        len(report.imported),
        report.rows,
        args.root,
        len(report.skipped),
    )
    if not report.imported:
        return 2
    return 1 if report.skipped else 0
