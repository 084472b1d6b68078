"""``oasis-torchrl record``: drive N envs and record the episodes as a LeRobot dataset.

Drivers: the ground-truth ``autopilot`` (embedded server only), a ``scripted`` open-loop drive
(``--script "throttle=0.5,steering=sine:0.3:40"``) or a saved ``policy`` (``--policy
file.pt``). Episodes still running when the requested number is reached are dropped. A remote
endpoint reads its key from ``DECART_API_KEY`` (never from a flag: command lines are visible to
every user of the machine); keys never reach the dataset.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from oasis_torchrl.commands._dataset_args import (
    add_dataset_arguments,
    quiet_dataset_libraries,
    sigterm_as_interrupt,
)

if TYPE_CHECKING:
    import numpy as np

    from oasis_torchrl.drivers import Driver
    from oasis_torchrl.envs import OasisEnv
    from oasis_torchrl.envs.episodes import Prompts

logger = logging.getLogger(__name__)

NAME = "record"
HELP = "drive the world model (autopilot, script or saved policy) and record a LeRobot dataset"

DRIVERS = ("autopilot", "scripted", "policy")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags: what to drive, how, how much, and where to write."""
    add_dataset_arguments(parser)
    parser.add_argument("--episodes", type=int, default=10, help="episodes to record (10)")
    parser.add_argument("--num-envs", type=int, default=2, help="concurrent sessions (2)")
    parser.add_argument("--driver", choices=DRIVERS, default="autopilot", help="who drives")
    parser.add_argument(
        "--script", default="throttle=0.5", help="scripted driver spec (throttle=...,steering=...)"
    )
    parser.add_argument("--policy", type=Path, help="saved policy (TorchScript or torch.save)")
    parser.add_argument(
        "--policy-in-keys",
        help="comma-separated inputs of a plain policy module, nested keys with dots "
        "(e.g. pixels.front,state)",
    )
    parser.add_argument(
        "--prompt",
        action="append",
        help="episode prompt, repeatable (each episode draws one; default 'urban street')",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the episode sequence (0)")
    parser.add_argument("--max-steps", type=int, default=128, help="chunks per episode (128)")
    parser.add_argument("--endpoint", default="local", help="'local' or an A2V endpoint URL")
    parser.add_argument("--width", type=int, default=768, help="embedded-server frame width")
    parser.add_argument("--height", type=int, default=512, help="embedded-server frame height")
    parser.add_argument(
        "--fps", type=int, default=20, help="world-model frame rate (embedded server: its rate)"
    )
    parser.add_argument(
        "--rows",
        choices=("frame", "chunk"),
        default="frame",
        help="one dataset row per frame (fps) or per 4-frame chunk (fps/4)",
    )


def _prompts(prompts: Sequence[str] | None) -> Prompts:
    """One prompt for every episode, or a sampler drawing one per episode."""
    choices = list(prompts or ["urban street"])
    if len(choices) == 1:
        return choices[0]

    def sample(row: int, rng: np.random.Generator) -> str:
        return choices[int(rng.integers(len(choices)))]

    return sample


def make_driver(args: argparse.Namespace) -> Driver:
    """The driver the flags ask for.

    Example:
        >>> args = argparse.Namespace(driver="scripted", script="throttle=0.3")
        >>> type(make_driver(args)).__name__
        'ScriptedDriver'
    """
    from oasis_torchrl.drivers import Autopilot, PolicyDriver, ScriptedDriver

    if args.driver == "autopilot":
        return Autopilot()
    if args.driver == "scripted":
        return ScriptedDriver.from_spec(args.script)
    if args.policy is None:
        raise ValueError("--driver policy needs --policy FILE")
    in_keys = None
    if args.policy_in_keys:
        in_keys = [tuple(key.split(".")) for key in args.policy_in_keys.split(",")]
    return PolicyDriver.load(args.policy, in_keys=in_keys)


def _make_env(args: argparse.Namespace) -> tuple[OasisEnv, int]:
    """The env and the world-model fps of the run."""
    from oasis_torchrl.envs import OasisEnv
    from oasis_torchrl.sim.config import ServerConfig

    server = ServerConfig(width=args.width, height=args.height, fps=float(args.fps))
    env = OasisEnv(
        args.endpoint,
        args.num_envs,
        _prompts(args.prompt),
        server=server,
        all_frames=args.rows == "frame",
        max_steps=args.max_steps,
    )
    env.set_seed(args.seed)
    return env, args.fps


def record(args: argparse.Namespace) -> int:
    """Drive until ``--episodes`` episodes are written; returns the number written."""
    from tqdm import tqdm

    from oasis_torchrl.data import LeRobotRecorder

    driver = make_driver(args)
    env, fps = _make_env(args)
    recorder = LeRobotRecorder(
        args.root,
        repo_id=args.repo_id,
        fps=fps,
        image_size=args.image_size,
        vcodec=args.vcodec,
        append=args.append,
        max_episodes=args.episodes,
        keep_unfinished=False,
    )
    try:
        with recorder, tqdm(total=args.episodes, unit="episode", desc="recording") as bar:
            td = env.reset()
            while not recorder.full:
                td, next_td = env.step_and_maybe_reset(driver(td))
                completed = recorder.write(td.unsqueeze(-1))
                bar.set_postfix(rows=recorder.rows_written, refresh=False)
                bar.update(completed)
                td = next_td
    finally:
        env.close()
    return recorder.episodes_written


def run(args: argparse.Namespace) -> int:
    """Record; exit code 0, 2 on bad settings, 130 when interrupted (SIGINT or SIGTERM; the
    completed episodes are kept)."""
    if args.episodes < 1 or args.num_envs < 1:
        logger.error("--episodes and --num-envs must be >= 1")
        return 2
    quiet_dataset_libraries()
    try:
        with sigterm_as_interrupt():
            written = record(args)
    except (ValueError, TypeError, KeyError, FileExistsError, FileNotFoundError) as error:
        logger.error("cannot record: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted; %s keeps every episode completed so far", args.root)
        return 130
    logger.info("wrote %d episodes to %s", written, args.root)
    return 0
