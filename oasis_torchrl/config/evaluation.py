"""Settings of an evaluation: the ``eval`` sections and the ``eval`` command."""

from __future__ import annotations

from dataclasses import dataclass

from oasis_torchrl.config.env import EnvConfig
from oasis_torchrl.options import option


@dataclass
class EvaluationConfig:
    """Fixed prompts and seeds a policy is evaluated on (one env row per episode)."""

    prompts: list[str] = option(default_factory=lambda: ["urban"], help="evaluation prompts")
    episodes: int = option(8, help="episodes per prompt and seed, one env row each (0: none)", ge=0)
    seeds: list[int] = option(default_factory=lambda: [1000], help="evaluation seeds")
    max_steps: int = option(150, help="chunks per episode", ge=1)
    rerun: str | None = option(
        None, help="record the episodes: an .rrd path, 'spawn' or a viewer URL"
    )
    lerobot: str | None = option(None, help="also record them as a LeRobot dataset here")
    compare: list[str] = option(
        default_factory=list,
        help="more driver specs recorded side by side with the evaluated policy, on the same "
        "seeds, into eval.rerun (the main job: among the policies it evaluates)",
    )
    divergence: float = option(
        0.25,
        help="side by side: throttle or steering further apart than this marks the first step "
        "where a policy leaves the first one",
    )

    def __post_init__(self) -> None:
        if self.episodes and (not self.prompts or not self.seeds):
            raise ValueError("eval needs at least one prompt and one seed")


@dataclass
class EvalConfig(EvaluationConfig):
    """``oasis-torchrl eval``: a policy, prompts and seeds in; distance, collision rate and
    return out (JSON)."""

    policy: str = option(
        "autopilot",
        help="the driver: autopilot | scripted:<script> (or constant:throttle=1.0,steering=0.0) "
        "| a shipped policy (pretrained:<name>) | a saved policy (a LeRobot policy folder of any "
        "type, a PPO checkpoint, a TorchScript or torch.save file) | a policy server "
        "(grpc://host:port; key in OASIS_POLICY_API_KEY)",
    )
    output: str | None = option(None, help="JSON file (the report is also printed)")
    progress: bool = option(True, help="tqdm progress bars")
    baseline: str | None = option(
        None,
        help="an earlier report (JSON) of the same prompts, seeds and episodes: the report adds "
        "the paired per-episode distance difference against it (vs_baseline)",
    )
    env: EnvConfig = option(
        default_factory=EnvConfig,
        help="the env (rows, prompts and episode length come from the evaluation settings; "
        "a network policy's own image size replaces env.image_size)",
    )
