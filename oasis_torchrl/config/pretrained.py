"""Settings of ``oasis-torchrl pretrained {list,path,ship}``: the shipped policies, where one is,
and shipping a trained policy with its card."""

from __future__ import annotations

from dataclasses import dataclass

from oasis_torchrl.config.env import EnvConfig
from oasis_torchrl.config.scenes import HELD_OUT_SCENES, HELD_OUT_SEEDS, REPORT_SEED
from oasis_torchrl.options import REQUIRED, option

BEST_CONSTANT = "constant:throttle=1.0,steering=0.0"
"""The best constant action: full throttle, straight ahead (the learning benchmark's sweep)."""


@dataclass
class PretrainedListConfig:
    """``oasis-torchrl pretrained list``: the shipped policies' names, one a line."""


@dataclass
class PretrainedPathConfig:
    """``oasis-torchrl pretrained path NAME``: the folder of a shipped policy (a LeRobot policy
    folder: ``lerobot-eval --policy.path=$(oasis-torchrl pretrained path ppo-scratch)``)."""

    name: str = option(REQUIRED, help="the shipped policy's name", positional=True)


@dataclass
class ShipConfig:
    """``oasis-torchrl pretrained ship POLICY NAME``: copy a trained policy folder into the
    shipped policies, evaluate it beside the best constant action on the report seed and on
    held-out scenes and seeds, and write its card (README.md and the training curve)."""

    policy: str = option(
        REQUIRED,
        help="the run's policy folder: <ppo run>/policy, or <demo run>/bc/round_<k>/policy",
        positional=True,
    )
    name: str = option(REQUIRED, help="the shipped policy's name", positional=True)
    prompts: list[str] = option(
        default_factory=lambda: ["urban"],
        help="the report's prompts (the main job's evaluation prompts)",
    )
    seeds: list[int] = option(default_factory=lambda: [REPORT_SEED], help="the report's seeds")
    held_out_prompts: list[str] = option(
        default_factory=lambda: list(HELD_OUT_SCENES),
        help="scenes no training prompt uses, each reported on its own",
    )
    held_out_seeds: list[int] = option(
        default_factory=lambda: list(HELD_OUT_SEEDS), help="seeds no config uses"
    )
    episodes: int = option(16, help="episodes per prompt and seed", ge=1)
    max_steps: int = option(150, help="chunks per episode", ge=1)
    baseline: str = option(BEST_CONSTANT, help="the driver every figure is compared with")
    commit: str | None = option(
        None, help="the commit that trained it (null: the source tree's commit when shipping)"
    )
    machine: str | None = option(
        None, help="the machine it trained on (null: this one's cores and CPU model)"
    )
    output: str | None = option(
        None, help="the folder of shipped policies to write into (null: the package's)"
    )
    env: EnvConfig = option(
        default_factory=EnvConfig,
        help="the evaluation env (the embedded server by default: distances need its ground truth)",
    )
    progress: bool = option(True, help="tqdm progress bars")

    def __post_init__(self) -> None:
        if not self.name or "/" in self.name or self.name.startswith("."):
            raise ValueError(f"a shipped policy's name is a plain folder name, got {self.name!r}")
