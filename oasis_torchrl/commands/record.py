"""``oasis-torchrl record``: drive N envs and record the episodes as a LeRobot dataset.

Drivers: the ground-truth ``autopilot`` (embedded server only), a ``scripted`` open-loop drive
(``--script "throttle=0.5,steering=sine:0.3:40"``) or a saved ``policy`` (``--policy
file.pt``). Episodes still running when the requested number is reached are dropped. A remote
endpoint reads its key from ``DECART_API_KEY`` (never from a flag: command lines are visible to
every user of the machine); keys never reach the dataset.

With ``--ray`` the sessions run on Ray workers (TorchRL's ``RayCollector``; a local runtime, or
a cluster with ``--ray-address``), each recording its share of the episodes into its own shard
under ``--shard-root``; the shards are then merged into ``--root``
(:func:`~oasis_torchrl.distributed.record_on_ray`).
"""

from __future__ import annotations

import argparse
import logging
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from oasis_torchrl.commands._dataset_args import (
    add_dataset_arguments,
    quiet_dataset_libraries,
    sigterm_as_interrupt,
)
from oasis_torchrl.commands._ray_args import (
    DEFAULT_BATCH_STEPS,
    add_ray_arguments,
    check_ray_flags,
    ray_config,
)

if TYPE_CHECKING:
    import numpy as np

    from oasis_torchrl.distributed import RayRecording
    from oasis_torchrl.drivers import DriverSpec
    from oasis_torchrl.envs import OasisEnv
    from oasis_torchrl.envs.episodes import Prompts

logger = logging.getLogger(__name__)

NAME = "record"
HELP = "drive the world model (autopilot, script or saved policy) and record a LeRobot dataset"

#: ``oasis_torchrl.drivers.DRIVER_KINDS``, spelled out: importing that module (torch) would cost
#: every CLI call 8 s; tests/data/test_drivers.py checks the two agree.
DRIVERS = ("autopilot", "scripted", "policy")
DEFAULT_NUM_ENVS = 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Flags: what to drive, how, how much, and where to write."""
    add_dataset_arguments(parser)
    parser.add_argument("--episodes", type=int, default=10, help="episodes to record (10)")
    parser.add_argument(
        "--num-envs", type=int, help=f"concurrent sessions, without --ray ({DEFAULT_NUM_ENVS})"
    )
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
    add_ray_arguments(parser)


def check_flags(args: argparse.Namespace) -> None:
    """Refuse flag combinations that mean nothing, naming the flags.

    Example:
        >>> check_flags(argparse.Namespace(ray=True, num_envs=None, append=True))
        Traceback (most recent call last):
        ...
        ValueError: --append does not work with --ray: record into a new --root
    """
    check_ray_flags(args)
    if not args.ray:
        return
    if args.num_envs is not None:
        raise ValueError(
            "--num-envs is for one process; with --ray use --collectors and --sessions-per-env"
        )
    if args.append:
        raise ValueError("--append does not work with --ray: record into a new --root")
    if args.server_address and args.endpoint != "local":
        raise ValueError("--server-address replaces --endpoint; give one of them")


def _prompts(prompts: Sequence[str] | None) -> Prompts:
    """One prompt for every episode, or a sampler drawing one per episode."""
    choices = list(prompts or ["urban street"])
    if len(choices) == 1:
        return choices[0]

    def sample(row: int, rng: np.random.Generator) -> str:
        return choices[int(rng.integers(len(choices)))]

    return sample


def driver_spec(args: argparse.Namespace) -> DriverSpec:
    """The driver the flags ask for, as a picklable spec (call it to build the driver).

    Example:
        >>> args = argparse.Namespace(driver="scripted", script="throttle=0.3", policy=None,
        ...                           policy_in_keys=None, fps=20)
        >>> type(driver_spec(args)()).__name__
        'ScriptedDriver'
    """
    from oasis_torchrl.drivers import DriverSpec

    if args.driver == "policy" and args.policy is None:
        raise ValueError("--driver policy needs --policy FILE")
    in_keys = None
    if args.policy_in_keys:
        in_keys = tuple(tuple(key.split(".")) for key in args.policy_in_keys.split(","))
    return DriverSpec(
        args.driver,
        script=args.script,
        policy=None if args.policy is None else args.policy.absolute(),  # Ray workers: other cwd
        policy_in_keys=in_keys,
    )


def _env_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """``OasisEnv`` arguments of every env of the run, whatever its width."""
    from oasis_torchrl.sim.config import ServerConfig

    return {
        "endpoint": args.endpoint,
        "prompts": _prompts(args.prompt),
        "server": ServerConfig(width=args.width, height=args.height, fps=float(args.fps)),
        "all_frames": args.rows == "frame",
        "max_steps": args.max_steps,
    }


def _recorder_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    """How the episodes are stored, in one dataset or in shards."""
    return {"fps": args.fps, "image_size": args.image_size, "vcodec": args.vcodec}


def _make_env(args: argparse.Namespace) -> OasisEnv:
    from oasis_torchrl.envs import OasisEnv

    env = OasisEnv(num_envs=args.num_envs or DEFAULT_NUM_ENVS, **_env_kwargs(args))
    env.set_seed(args.seed)
    return env


def record(args: argparse.Namespace, stop: threading.Event) -> int:
    """Drive until ``--episodes`` episodes are written or ``stop`` is set; returns the number
    written."""
    from tqdm import tqdm

    from oasis_torchrl.data import LeRobotRecorder

    driver = driver_spec(args)()
    env = _make_env(args)
    recorder = LeRobotRecorder(
        args.root,
        repo_id=args.repo_id,
        append=args.append,
        max_episodes=args.episodes,
        keep_unfinished=False,
        **_recorder_kwargs(args),
    )
    try:
        with recorder, tqdm(total=args.episodes, unit="episode", desc="recording") as bar:
            td = env.reset()
            while not recorder.full:
                if stop.is_set():
                    raise KeyboardInterrupt
                td, next_td = env.step_and_maybe_reset(driver(td))
                completed = recorder.write(td.unsqueeze(-1))
                bar.set_postfix(rows=recorder.rows_written, refresh=False)
                bar.update(completed)
                td = next_td
    finally:
        env.close()
    return recorder.episodes_written


def record_on_ray(args: argparse.Namespace) -> RayRecording:
    """Record on Ray workers and merge their shards into ``--root``."""
    from tqdm import tqdm

    from oasis_torchrl import distributed
    from oasis_torchrl.envs import OasisEnv

    config = ray_config(args, args.root)
    driver = driver_spec(args)
    driver()  # a bad script or policy file fails here, before any worker starts
    create_env = distributed.oasis_env_factory(OasisEnv, config, **_env_kwargs(args))
    logger.info(
        "recording on Ray (%s): %d workers x %d sessions, shards in %s",
        config.address,
        config.num_collectors,
        config.sessions_per_env,
        config.shard_root,
    )
    with tqdm(total=args.episodes, unit="episode", desc="recording") as bar:
        return distributed.record_on_ray(
            config,
            create_env,
            driver,
            args.root,
            episodes=args.episodes,
            batch_steps=DEFAULT_BATCH_STEPS if args.batch_steps is None else args.batch_steps,
            seed=args.seed,
            repo_id=args.repo_id,
            recorder_kwargs=_recorder_kwargs(args),
            keep_shards=args.keep_shards,
            progress=lambda episodes: bar.update(min(episodes, bar.total) - bar.n),
        )


def run(args: argparse.Namespace) -> int:
    """Record; exit code 0, 2 on bad settings, 1 when a lost Ray worker stopped the run (its
    finalized episodes are kept), 130 when interrupted (SIGINT or SIGTERM; the completed
    episodes are kept)."""
    if args.episodes < 1 or (args.num_envs is not None and args.num_envs < 1):
        logger.error("--episodes and --num-envs must be >= 1")
        return 2
    quiet_dataset_libraries()
    try:
        check_flags(args)
        with sigterm_as_interrupt() as stop:
            if args.ray:
                result = record_on_ray(args)
                written, stopped = result.episodes, result.stopped
            else:
                written, stopped = record(args, stop), False
    except (ValueError, TypeError, KeyError, FileExistsError, FileNotFoundError) as error:
        logger.error("cannot record: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted; %s keeps every episode completed so far", args.root)
        return 130
    if stopped:
        logger.error("a lost Ray worker stopped the run after %d episodes (%s)", written, args.root)
        return 1
    logger.info("wrote %d episodes to %s", written, args.root)
    return 0
