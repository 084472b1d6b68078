"""``oasis-torchrl view PATH``: show an ``.rrd``, a saved rollout or a LeRobot dataset in rerun;
``oasis-torchrl view A.rrd B.rrd``: two recordings side by side on one timeline
(settings: :class:`~oasis_torchrl.config.viewing.ViewConfig`)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from oasis_torchrl.config import to_object
from oasis_torchrl.config.viewing import ViewConfig

logger = logging.getLogger(__name__)

NAME = "view"
HELP = "show an .rrd, a saved rollout or a LeRobot dataset in rerun, or save it as .rrd"
CONFIG = ViewConfig


def _given(cfg: ViewConfig, *names: str) -> dict[str, Any]:
    """The options among ``names`` that are set (the library defaults the rest)."""
    return {name: getattr(cfg, name) for name in names if getattr(cfg, name) is not None}


def _replay_dataset(cfg: ViewConfig) -> None:
    from oasis_torchrl.viz.lerobot_replay import DatasetReplay
    from oasis_torchrl.viz.recording import open_recording

    recording = open_recording(cfg.target, **_given(cfg, "memory_limit"))
    try:
        replay = DatasetReplay(cfg.path, recording, **_given(cfg, "jpeg_quality"))
        replay.log(cfg.episodes)
    finally:
        recording.flush()
        recording.disconnect()


def _replay_rollout(cfg: ViewConfig) -> None:
    from oasis_torchrl.client import SceneSource
    from oasis_torchrl.viz.logger import RolloutLogger
    from oasis_torchrl.viz.options import LogOptions
    from oasis_torchrl.viz.replay import replay_rollout

    options = LogOptions(**_given(cfg, "rows", "jpeg_quality"))
    scenes = SceneSource(cfg.scenes) if cfg.scenes else None
    name = Path(cfg.path).resolve().name  # the saved rollout's: it names no policy
    with RolloutLogger(
        cfg.target, options, scenes=scenes, name=name, **_given(cfg, "memory_limit")
    ) as rollout_logger:
        replay_rollout(cfg.path, rollout_logger)


def _align(cfg: ViewConfig) -> None:
    from oasis_torchrl.viz.replay import RRD, source_kind
    from oasis_torchrl.viz.side_by_side import align_recordings

    for path in (cfg.path, cfg.beside):
        if source_kind(path) != RRD:
            raise ValueError(f"side by side needs two .rrd recordings; {path} is not one")
    roots = align_recordings([cfg.path, cfg.beside], cfg.target)
    logger.info("side by side: %s", ", ".join(f"{path} as {root}" for path, root in roots.items()))


def run(settings: DictConfig) -> int:
    """Open, replay or convert PATH; exit code 2 for bad input.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("view", ["path=/nowhere"]))
        2
    """
    from oasis_torchrl.viz.replay import DATASET, RRD, open_in_viewer, source_kind

    cfg: ViewConfig = to_object(settings)
    try:
        kind = source_kind(cfg.path)
        if cfg.beside is not None:
            _align(cfg)
        elif kind == RRD:
            if cfg.save is not None or cfg.connect is not None:
                raise ValueError(f"{cfg.path} is already a recording: open it without --save")
            open_in_viewer(cfg.path, **_given(cfg, "memory_limit"))
        elif kind == DATASET:
            _replay_dataset(cfg)
        else:
            _replay_rollout(cfg)
    except ValueError as error:
        logger.error("cannot view %s: %s", cfg.path, error)
        return 2
    if cfg.save is not None:
        logger.info("wrote %s", cfg.save)
    return 0
