"""``oasis-torchrl drive``: the autopilot drives one route on the embedded server, filmed by the
three cameras (a quick look at the simulator; the main job is ``oasis-torchrl demo``)."""

from __future__ import annotations

import argparse
import json
import logging

logger = logging.getLogger(__name__)

NAME = "drive"
HELP = "drive the embedded simulator with the autopilot and write a 3-camera video + summary"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Output folder, prompt, seed, length and camera size.

    Example:
        >>> add_arguments(parser := argparse.ArgumentParser())
        >>> parser.parse_args(["--steps", "5"]).output
        'outputs/drive'
    """
    parser.add_argument("--output", default="outputs/drive", help="output folder")
    parser.add_argument("--prompt", default="urban street, sunset", help="scene prompt")
    parser.add_argument("--seed", type=int, default=0, help="world seed")
    parser.add_argument("--steps", type=int, default=60, help="action chunks to drive")
    parser.add_argument("--width", type=int, default=768, help="camera width")
    parser.add_argument("--height", type=int, default=512, help="camera height")


def run(args: argparse.Namespace) -> int:
    """Drive, write ``drive.mp4`` and ``summary.json``, print the summary as JSON."""
    from oasis_torchrl.demo import drive_demo

    summary = drive_demo(
        args.output,
        prompt=args.prompt,
        seed=args.seed,
        steps=args.steps,
        width=args.width,
        height=args.height,
    )
    print(json.dumps(summary.__dict__, indent=2))  # the command's output, not library logging
    return 0
