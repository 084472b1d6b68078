"""``oasis-torchrl view PATH``: show an ``.rrd``, a saved rollout or a LeRobot dataset in rerun.

PATH is an ``.rrd`` file (opened in the native viewer), a LeRobot dataset folder (``--episodes``
chooses episodes) or a rollout saved with :func:`oasis_torchrl.viz.replay.save_rollout`
(``--rows`` chooses env rows). Rollouts and datasets go to a spawned viewer, to a running one
(``--connect``) or to a file (``--save out.rrd``).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

logger = logging.getLogger(__name__)

NAME = "view"
HELP = "show an .rrd, a saved rollout or a LeRobot dataset in rerun, or save it as .rrd"


def parse_indices(text: str) -> tuple[int, ...]:
    """``"0,3,5"`` -> ``(0, 3, 5)``.

    Example:
        >>> parse_indices("0, 3,5")
        (0, 3, 5)
        >>> parse_indices("a")
        Traceback (most recent call last):
        ...
        argparse.ArgumentTypeError: expected comma-separated non-negative integers, got 'a'
    """
    try:
        values = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        values = ()
    if not values or min(values) < 0:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated non-negative integers, got {text!r}"
        )
    return values


def parse_quality(text: str) -> int:
    """A JPEG quality, 1-100.

    Example:
        >>> parse_quality("70")
        70
    """
    if not text.isdigit() or not 1 <= int(text) <= 100:
        raise argparse.ArgumentTypeError(f"JPEG quality must be an integer 1-100, got {text!r}")
    return int(text)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """PATH, what to show, and where to send it."""
    parser.add_argument(
        "path", type=Path, help=".rrd file, LeRobot dataset folder or saved rollout folder"
    )
    parser.add_argument(
        "--episodes", type=parse_indices, help="dataset episodes to show, e.g. 0,3,5 (default all)"
    )
    parser.add_argument(
        "--rows", type=parse_indices, help="rollout env rows to show, e.g. 0,5 (default all)"
    )
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--save", type=Path, metavar="OUT.rrd", help="write an .rrd file instead")
    where.add_argument(
        "--connect",
        metavar="URL",
        help="send to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy",
    )
    parser.add_argument(
        "--memory-limit", help="memory limit of a spawned viewer, e.g. 4GB or 50%% (default 25%%)"
    )
    parser.add_argument(
        "--jpeg-quality", type=parse_quality, help="JPEG quality 1-100 of frames (default 85)"
    )


def _target(args: argparse.Namespace) -> str:
    if args.save is not None:
        return str(args.save)
    return args.connect or "spawn"


def _given(args: argparse.Namespace, *names: str) -> dict[str, object]:
    """The options among ``names`` set on the command line (the library defaults the rest)."""
    return {name: getattr(args, name) for name in names if getattr(args, name) is not None}


def _replay_dataset(args: argparse.Namespace) -> None:
    from oasis_torchrl.viz.lerobot_replay import DatasetReplay
    from oasis_torchrl.viz.recording import open_recording

    recording = open_recording(_target(args), **_given(args, "memory_limit"))
    try:
        replay = DatasetReplay(args.path, recording, **_given(args, "jpeg_quality"))
        replay.log(args.episodes)
    finally:
        recording.flush()
        recording.disconnect()


def _replay_rollout(args: argparse.Namespace) -> None:
    from oasis_torchrl.viz.logger import RolloutLogger
    from oasis_torchrl.viz.options import LogOptions
    from oasis_torchrl.viz.replay import replay_rollout

    options = LogOptions(**_given(args, "rows", "jpeg_quality"))
    with RolloutLogger(_target(args), options, **_given(args, "memory_limit")) as rollout_logger:
        replay_rollout(args.path, rollout_logger)


def run(args: argparse.Namespace) -> int:
    """Open, replay or convert PATH; exit code 2 for bad input."""
    from oasis_torchrl.viz.replay import DATASET, RRD, open_in_viewer, source_kind

    try:
        kind = source_kind(args.path)
        if kind == RRD:
            if args.save is not None or args.connect is not None:
                raise ValueError(f"{args.path} is already a recording: open it without --save")
            open_in_viewer(args.path, **_given(args, "memory_limit"))
        elif kind == DATASET:
            _replay_dataset(args)
        else:
            _replay_rollout(args)
    except ValueError as error:
        logger.error("cannot view %s: %s", args.path, error)
        return 2
    if args.save is not None:
        logger.info("wrote %s", args.save)
    return 0
