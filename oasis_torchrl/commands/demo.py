"""``oasis-torchrl demo``: the main job on the embedded server (what ``make demo`` runs)."""

from __future__ import annotations

import argparse
import json
import logging

logger = logging.getLogger(__name__)

NAME = "demo"
HELP = "drive the embedded simulator with the autopilot and write a 3-camera video + summary"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--output", default="outputs/demo", help="output folder")
    parser.add_argument("--prompt", default="urban street, sunset", help="scene prompt")
    parser.add_argument("--seed", type=int, default=0, help="world seed")
    parser.add_argument("--steps", type=int, default=60, help="action chunks to drive")
    parser.add_argument("--width", type=int, default=768, help="camera width")
    parser.add_argument("--height", type=int, default=512, help="camera height")


def run(args: argparse.Namespace) -> int:
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
