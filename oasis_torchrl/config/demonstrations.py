"""Settings of the main job's demonstrations (``record``): who demonstrates, how many episodes,
the noise on the executed actions and the late reactions.

A leaf of the config package (:mod:`oasis_torchrl.options` only): the late-reacting autopilot
(:mod:`oasis_torchrl.drivers.late_reaction`) checks its reaction range with
:func:`reaction_range` without depending on the main job's settings.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from oasis_torchrl.options import option


@dataclass
class NoiseConfig:
    """Ornstein-Uhlenbeck noise on the executed actions (DART): per-chunk innovation
    standard deviations and their correlation from chunk to chunk."""

    throttle: float = option(0.1, help="throttle innovation std")
    steering: float = option(0.02, help="steering innovation std")
    correlation: float = option(0.8, help="chunk-to-chunk correlation in [0, 1)")


def reaction_range(reaction: Sequence[float], name: str = "reaction") -> tuple[float, float]:
    """``(near, far)`` metres of a late reaction, checked: two numbers, ``0 <= near <= far``.

    Example:
        >>> reaction_range([8, 40])
        (8.0, 40.0)
        >>> reaction_range([40, 8], "record.late_reaction")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: record.late_reaction must be [near, far] metres with 0 <= near <= far, ...
    """
    values = [float(value) for value in reaction]
    if len(values) != 2 or not 0 <= values[0] <= values[1]:
        raise ValueError(
            f"{name} must be [near, far] metres with 0 <= near <= far, got {list(reaction)}"
        )
    return values[0], values[1]


@dataclass
class DemonstrationsConfig:
    """The demonstrations (frame rows, a LeRobot dataset): the autopilot's where the endpoint
    sends ground truth, else a policy's or a person's."""

    source: str = option(
        "auto",
        help="who demonstrates: auto (the autopilot where the endpoint sends ground truth) | "
        "autopilot | a policy (a saved policy folder or checkpoint, grpc://host:port, or a "
        "driver spec) | a LeRobot dataset folder of frame rows (a person's drives recorded "
        "with lerobot-record and the keyboard teleoperators, or an earlier recording)",
    )
    episodes: int = option(16, help="episodes to record")
    seed: int = option(1, help="seed of their episodes and noise")
    noise: NoiseConfig = option(default_factory=NoiseConfig, help="executed-action noise")
    # Late reactions record the states a clone reaches when it misses the early cue (the
    # autopilot's own drives change lanes 30-45 m ahead and hold none of them); with the
    # manoeuvre loss and enough demonstrations they are what makes a clone avoid obstacles
    # (docs/experiments/2026-11-28-bc-without-dagger.md).
    late_reaction: list[float] | None = option(
        default_factory=lambda: [8.0, 40.0],
        help="[near, far] metres: the executed car keeps its lane until the obstacle in it is "
        "nearer than a distance drawn in this range for each approach, labelled by the "
        "autopilot throughout (null: the autopilot drives)",
    )

    def __post_init__(self) -> None:
        if self.late_reaction is not None:
            reaction_range(self.late_reaction, "record.late_reaction")
