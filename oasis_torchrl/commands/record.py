"""``oasis-torchrl record``: drive N envs and record the episodes as a LeRobot dataset.

Drivers: ``auto`` (the default: the autopilot where the endpoint sends ground truth, else the
script), the ground-truth ``autopilot`` (embedded server only), a ``scripted`` open-loop drive
(``--script "throttle=0.5,steering=sine:0.3:40"``) or a ``policy``, saved (``--policy
file.pt``) or served (``--policy grpc://host:port``, the key in ``OASIS_POLICY_API_KEY``).
Episodes still running when the requested number is reached are dropped. A remote endpoint
reads its key from ``DECART_API_KEY`` (never from a flag: command lines are visible to every
user of the machine); keys never reach the dataset.

With ``--ray`` the sessions run on Ray workers (TorchRL's ``RayCollector``; a local runtime, or
a cluster with ``--ray-address``), each recording its share of the episodes into its own shard
under ``--shard-root``; the shards are then merged into ``--root``
(:func:`~oasis_torchrl.distributed.record_on_ray`). Settings:
:class:`~oasis_torchrl.config.recording.RecordConfig`.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omegaconf import DictConfig

from oasis_torchrl.commands._signals import sigterm_as_interrupt
from oasis_torchrl.config import to_object
from oasis_torchrl.config.env import AUTO
from oasis_torchrl.config.recording import RecordConfig

if TYPE_CHECKING:
    from tensordict import TensorDictBase
    from torchrl.envs import TransformedEnv

    from oasis_torchrl.distributed import RayRecording
    from oasis_torchrl.drivers import Driver, DriverSpec

logger = logging.getLogger(__name__)

NAME = "record"
HELP = "drive the world model (autopilot, script or saved policy) and record a LeRobot dataset"
CONFIG = RecordConfig


def driver_spec(cfg: RecordConfig) -> DriverSpec:
    """The driver the settings ask for, as a picklable spec (call it to build the driver).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> cfg = to_object(load_config("record", ["root=out", "driver=scripted"]))
        >>> type(driver_spec(cfg)()).__name__
        'ScriptedDriver'
    """
    from oasis_torchrl.drivers import DriverSpec

    in_keys = None
    if cfg.policy_in_keys:
        in_keys = tuple(tuple(key.split(".")) for key in cfg.policy_in_keys.split(","))
    spec = cfg.driver_spec
    if cfg.driver == AUTO:
        from oasis_torchrl.envs.capabilities import env_capabilities

        expert = env_capabilities(cfg.env).ground_truth
        spec = "autopilot" if expert else f"scripted:{cfg.script}"
        logger.info("driver auto: %s", spec)
    return DriverSpec(spec, in_keys=in_keys)


def _recorder_kwargs(cfg: RecordConfig) -> dict[str, Any]:
    """How the episodes are stored, in one dataset or in shards; a codec or quality the
    encoder cannot use fails here, before any env or worker starts."""
    from oasis_torchrl.data.writer import camera_encoder

    camera_encoder(cfg.vcodec, cfg.crf)
    size = None if cfg.image_size is None else tuple(cfg.image_size)
    return {"fps": cfg.env.server.fps, "image_size": size, "vcodec": cfg.vcodec, "crf": cfg.crf}


def _make_env(cfg: RecordConfig, driver: Driver) -> TransformedEnv:
    from oasis_torchrl.envs import make_env

    env = make_env(
        cfg.env,
        all_frames=cfg.rows == "frame",
        frame_stack=driver.frame_stack,
        expert=driver.needs_expert,
        front_crop=driver.front_crop,
    )
    env.set_seed(cfg.seed)
    return env


def record(cfg: RecordConfig, stop: threading.Event) -> int:
    """Drive until ``episodes`` episodes are written or ``stop`` is set; returns the number
    written."""
    from tqdm import tqdm

    from oasis_torchrl.data import LeRobotRecorder
    from oasis_torchrl.envs.driving import drive

    storage = _recorder_kwargs(cfg)
    driver = driver_spec(cfg)()
    env = _make_env(cfg, driver)
    recorder = LeRobotRecorder(
        cfg.root,
        repo_id=cfg.repo_id,
        append=cfg.append,
        max_episodes=cfg.episodes,
        keep_unfinished=False,
        **storage,
    )
    try:
        with recorder, tqdm(total=cfg.episodes, unit="episode", desc="recording") as bar:

            def write(td: TensorDictBase) -> None:
                if stop.is_set():  # a signal whose KeyboardInterrupt a library swallowed
                    raise KeyboardInterrupt
                bar.update(recorder.write(td.unsqueeze(-1)))
                bar.set_postfix(rows=recorder.rows_written, refresh=False)

            drive(env, driver, write, until=lambda: recorder.full)
    finally:
        env.close()
    return recorder.episodes_written


def record_on_ray(cfg: RecordConfig) -> RayRecording:
    """Record on Ray workers and merge their shards into ``root``."""
    from tqdm import tqdm

    from oasis_torchrl import distributed

    ray = cfg.ray
    if ray.shard_root is None:  # beside the dataset, so a cluster's nodes share it too
        root = Path(cfg.root)
        ray = replace(ray, shard_root=str(root.with_name(root.name + ".shards")))
    driver = driver_spec(cfg)
    expert = driver().needs_expert  # a bad script or policy file fails here, before any worker
    create_env = distributed.env_factory(
        cfg.env, ray, all_frames=cfg.rows == "frame", expert=expert
    )
    logger.info(
        "recording on Ray (%s): %d workers x %d sessions, shards in %s",
        ray.address,
        ray.num_collectors,
        ray.sessions_per_env,
        ray.shard_root,
    )
    with tqdm(total=cfg.episodes, unit="episode", desc="recording") as bar:
        return distributed.record_on_ray(
            ray,
            create_env,
            driver,
            cfg.root,
            episodes=cfg.episodes,
            batch_steps=ray.batch_steps,
            seed=cfg.seed,
            repo_id=cfg.repo_id,
            recorder_kwargs=_recorder_kwargs(cfg),
            keep_shards=ray.keep_shards,
            progress=lambda episodes: bar.update(min(episodes, bar.total) - bar.n),
        )


def run(settings: DictConfig) -> int:
    """Record; exit code 0, 2 on bad settings, 1 when a lost Ray worker stopped the run (its
    finalized episodes are kept), 130 when interrupted (SIGINT or SIGTERM; the completed
    episodes are kept).

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("record", ["root=/tmp/never", "driver=policy", "policy=nowhere.pt"]))
        2
    """
    from oasis_torchrl.data.quiet import quiet_dataset_libraries
    from oasis_torchrl.remote import RemotePolicyError

    cfg: RecordConfig = to_object(settings)
    quiet_dataset_libraries()
    try:
        with sigterm_as_interrupt() as stop:
            if cfg.ray.enabled:
                result = record_on_ray(cfg)
                written, stopped = result.episodes, result.stopped
            else:
                written, stopped = record(cfg, stop), False
    except (
        ValueError,
        TypeError,
        KeyError,
        FileExistsError,
        FileNotFoundError,
        RemotePolicyError,
    ) as error:
        logger.error("cannot record: %s", error)
        return 2
    except KeyboardInterrupt:
        logger.warning("interrupted; %s keeps every episode completed so far", cfg.root)
        return 130
    if stopped:
        logger.error("a lost Ray worker stopped the run after %d episodes (%s)", written, cfg.root)
        return 1
    logger.info("wrote %d episodes to %s", written, cfg.root)
    return 0
