"""Autopilot demonstrations for behaviour cloning, recorded with DART-style noise injection.

A clone of clean demonstrations only ever saw the car centred in its lane at the expert's
speed; its own small errors then take it where it has no data, and they compound (it drifts
off the road). Here the env executes the autopilot's chunk plus temporally correlated noise,
so the car wanders off the expert's path, while the dataset stores the autopilot's *clean*
action for every visited state: exactly the corrections the clone needs (Laskey et al., DART,
2017). The noise is an Ornstein-Uhlenbeck process per env row and channel, constant within a
chunk, reset with the row's episode.

With a ``learner``, the learner's own (noisy) actions are executed instead, still labelled by
the autopilot: a DAgger round (Ross et al., 2011), which collects the states the clone itself
reaches, e.g. an obstacle seen late at full speed, with what the expert would do there. The
same ``learner`` argument records late-reacting drives before any clone exists
(:class:`~oasis_torchrl.drivers.late_reaction.LateReactionAutopilot`, ``record.late_reaction``).

With a ``labeller`` (a saved or served policy, or any driver that needs no expert) it labels in
the autopilot's place: what an endpoint that sends frames only (the hosted service) allows.

Episodes are written through :class:`~oasis_torchrl.data.LeRobotRecorder`, one row per frame,
with each frame's privileged state (the target of behaviour cloning's auxiliary loss) where the
endpoint sends it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import torch
from omegaconf import DictConfig
from tensordict import TensorDictBase
from tqdm import tqdm

from oasis_torchrl.drivers import Autopilot, Driver
from oasis_torchrl.envs.driving import drive
from oasis_torchrl.envs.factory import make_env

logger = logging.getLogger(__name__)

LABEL = "label"
"""Key of the autopilot's clean action, stored as the row's action in place of the executed one."""


@dataclass(frozen=True)
class ActionNoise:
    """Ornstein-Uhlenbeck noise on executed actions: ``n <- correlation * n + std * eps``.

    ``throttle`` and ``steering`` are the per-chunk innovation standard deviations (the
    stationary deviation is ``std / sqrt(1 - correlation**2)``).

    Example:
        >>> noise = ActionNoise(throttle=0.0, steering=0.1, correlation=0.8)
        >>> round(noise.stationary_std()[1], 3)
        0.167
    """

    throttle: float = 0.1
    steering: float = 0.1
    correlation: float = 0.8

    def __post_init__(self) -> None:
        if min(self.throttle, self.steering) < 0 or not 0 <= self.correlation < 1:
            raise ValueError(f"noise stds must be >= 0 and correlation in [0, 1): {self}")

    def stationary_std(self) -> tuple[float, float]:
        """Long-run standard deviation of the throttle and steering noise."""
        factor = (1 - self.correlation**2) ** -0.5
        return self.throttle * factor, self.steering * factor


class NoiseProcess:
    """The per-row noise state of :class:`ActionNoise`.

    Example:
        >>> process = NoiseProcess(ActionNoise(), rows=3, seed=0)
        >>> process.step().shape
        torch.Size([3, 2])
        >>> process.reset(torch.tensor([True, False, False]))
        >>> process.value[0].tolist()
        [0.0, 0.0]
    """

    def __init__(self, noise: ActionNoise, rows: int, seed: int) -> None:
        self.noise = noise
        self.std = torch.tensor([noise.throttle, noise.steering])
        self.value = torch.zeros(rows, 2)
        self.generator = torch.Generator().manual_seed(seed)

    def step(self) -> torch.Tensor:
        """Advance one chunk; the new noise ``[rows, 2]``."""
        innovation = torch.randn(self.value.shape, generator=self.generator) * self.std
        self.value = self.noise.correlation * self.value + innovation
        return self.value

    def reset(self, rows: torch.Tensor) -> None:
        """Zero the noise of the rows where the bool mask ``rows`` is True."""
        self.value[rows] = 0.0


def record_demonstrations(
    env_cfg: DictConfig,
    root: str | Path,
    *,
    episodes: int,
    seed: int,
    noise: ActionNoise,
    learner: Driver | None = None,
    labeller: Driver | None = None,
    progress: bool = True,
) -> Path:
    """Record ``episodes`` labelled episodes at ``root`` (appended if it exists).

    Args:
        env_cfg: the ``env`` config section (prompts, rows, episode length, sizes).
        root: dataset folder; an existing dataset gets the new episodes appended.
        episodes: complete episodes to write (episodes still running at the end are dropped).
        seed: seeds the env's episodes and the noise.
        noise: the executed-action noise (all zeros records clean demonstrations).
        learner: a driver (run deterministically) whose actions are executed
            instead of the labeller's (DAgger); the labels stay the labeller's.
        labeller: the driver whose clean actions label every row (default: the autopilot, which
            needs the embedded server's expert).
        progress: show a progress bar.

    Example:
        >>> record_demonstrations(cfg.env, "demos", episodes=16, seed=1,
        ...                       noise=ActionNoise())  # doctest: +SKIP
    """
    from oasis_torchrl.data import LeRobotRecorder
    from oasis_torchrl.data.quiet import quiet_dataset_libraries

    # Here rather than in each caller: a DAgger round may record into a reused dataset without
    # the main job's first recording having run; the writer keeps it quiet from then on.
    quiet_dataset_libraries()
    expert = Autopilot() if labeller is None else labeller
    driver = learner or labeller or expert
    env = make_env(
        env_cfg,
        frame_stack=driver.frame_stack,
        expert=expert.needs_expert,
        front_crop=driver.front_crop,
    )
    env.set_seed(seed)
    rows = int(env.batch_size[0])
    process = NoiseProcess(noise, rows, seed)
    append = (Path(root) / "meta" / "info.json").exists()
    privileged = bool(env.base_env.ground_truth)
    recorder = LeRobotRecorder(
        root, max_episodes=episodes, keep_unfinished=False, append=append, privileged=privileged
    )

    def act(td: TensorDictBase) -> TensorDictBase:
        label = expert(td.clone(False)).get("action")
        driven = label if learner is None else learner(td.clone(False)).get("action")
        td.set(LABEL, label)
        return td.set("action", (driven + process.step().unsqueeze(1)).clamp(-1.0, 1.0))

    try:
        with (
            recorder,
            tqdm(total=episodes, desc="recording", unit="episode", disable=not progress) as bar,
        ):

            def write(td: TensorDictBase) -> None:
                labelled = td.set("action", td.get(LABEL)).exclude(LABEL)
                bar.update(recorder.write(labelled.unsqueeze(-1)))
                process.reset(td.get(("next", "done")).reshape(rows))

            drive(env, act, write, until=lambda: recorder.full)
    finally:
        env.close()
    logger.info("recorded %d episodes into %s", recorder.episodes_written, root)
    return Path(root)
