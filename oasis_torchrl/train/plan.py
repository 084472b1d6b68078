"""The main job's plan: everything a run does, resolved once, before its first stage.

:func:`plan_run` reads a :class:`~oasis_torchrl.config.DemoConfig` and asks the endpoint what
it sends (:func:`~oasis_torchrl.envs.capabilities.env_capabilities`, once), then settles who
demonstrates and who labels (:class:`Demonstrators`), where every product goes, and each
stage's complete settings: the demonstrations (:class:`RecordPlan`), the clone rounds
(:class:`CloneRound`, with their DAgger recordings, :class:`DaggerRound`), PPO fine-tuning and
the final evaluation (:class:`EvaluationPlan`). A bad setting, an unknown shipped policy or a
frames-only endpoint without a source fails here, before anything is written.

The plan is frozen and its configs are read-only: a stage takes its part
(:mod:`oasis_torchrl.train.stages`) and returns its product; whether it resumes or records is
an argument of the stage's function, never a change to the plan.
"""

from __future__ import annotations

import copy
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.config import load_config
from oasis_torchrl.config.env import AUTO
from oasis_torchrl.drivers import AUTOPILOT, pretrained_path, shipped_policies
from oasis_torchrl.drivers.pretrained import PREFIX as PRETRAINED
from oasis_torchrl.envs.capabilities import Capabilities, env_capabilities
from oasis_torchrl.train.demonstrations import ActionNoise
from oasis_torchrl.viz.recording import describe_target

logger = logging.getLogger(__name__)

SHARED_EVAL_KEYS = ("prompts", "seeds", "max_steps")
"""``eval`` keys PPO's own evaluations take from the pipeline's (how many and how often stay
the ``ppo.eval`` settings')."""
REFERENCE_KEY = "reference"


def frozen(cfg: DictConfig) -> DictConfig:
    """A read-only copy of ``cfg`` (what a merge with it makes is read-only too).

    Example:
        >>> frozen(OmegaConf.create({"a": 1})).a = 2
        Traceback (most recent call last):
        ...
        omegaconf.errors.ReadonlyConfigError: Cannot change read-only config container...
    """
    copied = copy.deepcopy(cfg)
    OmegaConf.set_readonly(copied, True)
    return copied


@dataclass(frozen=True)
class Demonstrators:
    """Who demonstrates and who labels the DAgger rounds, for what the endpoint sends.

    Example:
        >>> cfg = load_config("demo")
        >>> Demonstrators.of(cfg, env_capabilities(cfg.env))
        Demonstrators(source='autopilot', labeller='autopilot', ground_truth=True)
        >>> Demonstrators.of(cfg, Capabilities("the hosted service", ground_truth=False))
        Traceback (most recent call last):
        ...
        ValueError: the demonstrations need a source: the hosted service sends frames only ...
    """

    source: str
    """A driver spec (recorded from), a LeRobot dataset folder or a recordings folder."""
    labeller: str | None
    """The DAgger rounds' labeller (a driver spec); None: no rounds."""
    ground_truth: bool

    @classmethod
    def of(cls, cfg: DictConfig, capabilities: Capabilities) -> Demonstrators:
        """Resolve ``record.source`` and ``dagger.labeller`` (``auto``: the autopilot where the
        endpoint sends ground truth; elsewhere the source must be given)."""
        source, labeller = str(cfg.record.source), str(cfg.dagger.labeller)
        if source == AUTO and capabilities.frames_only:
            raise ValueError(
                f"the demonstrations need a source: {capabilities.endpoint} sends frames only "
                "(no autopilot); pass record.source=<a policy folder, checkpoint or "
                "grpc://host:port>, or a LeRobot dataset of a person's drives (lerobot-record "
                "with the keyboard teleoperators), or a folder of recordings in the reference "
                "format (episode_*/manifest.jsonl)"
            )
        source = AUTOPILOT if source == AUTO else source
        recorded = is_dataset(source) or is_recordings(source)
        if labeller == AUTO:
            labeller = AUTOPILOT if capabilities.ground_truth else None if recorded else source
        for name, spec in (("record.source", source), ("dagger.labeller", labeller)):
            if spec == AUTOPILOT:
                capabilities.require(
                    f"{name}=autopilot", f"pass a policy or a person's drives as {name}"
                )
        return cls(source, labeller, capabilities.ground_truth)


def is_dataset(source: str | Path) -> bool:
    """Whether ``source`` is a LeRobot dataset folder."""
    return (Path(source) / "meta" / "info.json").is_file()


def is_recordings(source: str | Path) -> bool:
    """Whether ``source`` is a folder of recordings in the reference format."""
    return any(Path(source).glob("episode_*/manifest.jsonl"))


@dataclass(frozen=True)
class Recording:
    """Episodes to record: ``labeller`` labels every row, ``learner`` (if any) drives, with
    ``noise`` on the executed actions
    (:func:`~oasis_torchrl.train.demonstrations.record_demonstrations`)."""

    env: DictConfig
    episodes: int
    seed: int
    noise: ActionNoise
    labeller: str
    """A driver spec; ``autopilot`` is the embedded server's expert."""
    learner: str | None = None
    """A driver spec; None: the labeller drives (or the late-reacting autopilot)."""
    late_reaction: tuple[float, float] | None = None
    """``[near, far]`` metres: the autopilot drives, reacting late."""
    progress: bool = True


@dataclass(frozen=True)
class RecordPlan:
    """The demonstrations: a given dataset, recordings to import, or episodes to record.

    Example:
        >>> plan = plan_run(load_config("demo", ["output_dir=/tmp/d"])).record
        >>> plan.dataset, plan.given, plan.recordings, plan.recording.episodes
        (PosixPath('/tmp/d/demos'), False, None, 16)
    """

    dataset: Path
    """Where the demonstrations are (a given dataset) or go (imported or recorded)."""
    given: bool
    """Whether ``dataset`` is ``record.source`` itself, only read."""
    recordings: Path | None
    """A folder of recordings in the reference format to import; None: record."""
    recording: Recording
    image_size: tuple[int, int]

    @classmethod
    def of(cls, cfg: DictConfig, demonstrators: Demonstrators) -> RecordPlan:
        """The demonstrations of ``cfg.record`` by ``demonstrators.source``, under
        ``<output_dir>/demos``."""
        reaction = cfg.record.late_reaction
        late = reaction is not None and demonstrators.source == AUTOPILOT
        recording = Recording(
            frozen(cfg.env),
            cfg.record.episodes,
            cfg.record.seed,
            ActionNoise(**cfg.record.noise),
            labeller=demonstrators.source,
            late_reaction=tuple(reaction) if late else None,
            progress=cfg.progress,
        )
        given = is_dataset(demonstrators.source)
        dataset = Path(demonstrators.source) if given else Path(cfg.output_dir) / "demos"
        recordings = Path(demonstrators.source) if is_recordings(demonstrators.source) else None
        return cls(dataset, given, recordings, recording, tuple(cfg.env.image_size))


@dataclass(frozen=True)
class DaggerRound:
    """A DAgger round's data: the previous clone drives ``recording``'s episodes into
    ``episodes``; those and ``previous`` (the data the previous clone learned) make ``data``."""

    recording: Recording
    episodes: Path
    previous: Path
    data: Path


@dataclass(frozen=True)
class CloneRound:
    """Clone round k: behaviour cloning from scratch (k = 0) or DAgger round k's fine-tuning of
    the previous clone, as ``config`` (a complete :class:`~oasis_torchrl.config.BCConfig`).

    Example:
        >>> rounds = plan_run(load_config("demo", ["output_dir=/tmp/d"])).clone
        >>> [str(round_.policy) for round_ in rounds]
        ['/tmp/d/bc/round_0/policy', '/tmp/d/bc/round_1/policy']
        >>> config = rounds[1].config
        >>> config.init_from, config.dataset.root, config.train.steps
        ('/tmp/d/bc/round_0/policy', '/tmp/d/bc/round_1/dataset', 500)
    """

    folder: Path
    config: DictConfig
    dagger: DaggerRound | None

    @property
    def policy(self) -> Path:
        """The round's policy folder."""
        return self.folder / "policy"


def clone_rounds(
    cfg: DictConfig, record: RecordPlan, demonstrators: Demonstrators
) -> tuple[CloneRound, ...]:
    """The first clone and the DAgger rounds (none without a labeller), each writing in
    ``<output_dir>/bc/round_<k>``."""
    rounds = cfg.dagger.rounds if demonstrators.labeller is not None else 0
    if rounds < cfg.dagger.rounds:
        logger.info("no DAgger rounds: demonstrations from a dataset have no labeller")
    planned: list[CloneRound] = []
    data = record.dataset
    for round_ in range(rounds + 1):
        folder = Path(cfg.output_dir) / "bc" / f"round_{round_}"
        values: dict[str, Any] = {"seed": cfg.seed + round_, "output_dir": str(folder)}
        dagger = None
        if round_:
            previous = planned[-1].policy
            recording = Recording(
                frozen(cfg.env),
                cfg.dagger.episodes,
                cfg.record.seed + 1000 * round_,
                ActionNoise(**cfg.dagger.noise),
                labeller=str(demonstrators.labeller),
                learner=str(previous),
                progress=cfg.progress,
            )
            dagger = DaggerRound(recording, folder / "dagger", data, folder / "dataset")
            data = dagger.data
            values |= {"init_from": str(previous), "train": {"steps": cfg.dagger.steps}}
        config = _bc_config(cfg, data, values, demonstrators.ground_truth)
        planned.append(CloneRound(folder, config, dagger))
    return tuple(planned)


def _bc_config(
    cfg: DictConfig, data: Path, values: dict[str, Any], ground_truth: bool
) -> DictConfig:
    """A clone round's BC config: the ``bc`` stage settings, the env's policy images, the
    round's ``values``, no evaluation of its own."""
    policy: dict[str, Any] = {
        "image_size": list(cfg.env.image_size),
        "front_crop": cfg.env.front_crop,
    }
    if not ground_truth:  # no privileged state in the demonstrations
        policy["aux_weight"] = 0.0
    shared = {"progress": cfg.progress, "dataset": {"root": str(data)}, "eval": {"episodes": 0}}
    merged = OmegaConf.merge(load_config("bc"), _plain(cfg.bc), shared, {"policy": policy}, values)
    return frozen(merged)


def ppo_config(
    cfg: DictConfig, init_from: Path | None, name: str = "ppo", *, fine_tune: bool = True
) -> DictConfig:
    """The PPO config of a pipeline config: the ``ppo`` stage settings (for fine-tuning; PPO
    from scratch takes the defaults), the shared ``env``, the evaluated prompts, seeds and
    episode length of the shared ``eval``, and a warm start from ``init_from``.

    Example:
        >>> ppo = ppo_config(load_config("demo", ["output_dir=/tmp/d"]), Path("/tmp/d/p"))
        >>> ppo.output_dir, ppo.init_from, ppo.eval.max_steps
        ('/tmp/d/ppo', '/tmp/d/p', 150)
    """
    values = {
        "seed": cfg.seed,
        "progress": cfg.progress,
        "output_dir": str(Path(cfg.output_dir) / name),
        "init_from": None if init_from is None else str(init_from),
        "env": cfg.env,
        "eval": {key: cfg.eval[key] for key in SHARED_EVAL_KEYS},
    }
    return OmegaConf.merge(load_config("ppo"), _plain(cfg.ppo) if fine_tune else {}, values)


def _plain(stage: DictConfig) -> dict[str, Any]:
    """A stage's settings as plain values, to merge into the stand-alone config that holds them
    (a typed section only merges into a config of its own type)."""
    return OmegaConf.to_container(stage, resolve=True)


@dataclass(frozen=True)
class EvaluationPlan:
    """Evaluations on a config's fixed prompts and seeds (its ``env`` and ``eval``), with the
    recording ``eval.rerun`` and ``eval.lerobot`` ask for or without.

    Example:
        >>> plan = EvaluationPlan.of(load_config("demo", ["output_dir=/tmp/d"]))
        >>> plan.settings(record=True).rerun, plan.settings(record=False).rerun, plan.recording
        ('/tmp/d/eval.rrd', None, PosixPath('/tmp/d/eval.rrd'))
    """

    env: DictConfig
    recorded: DictConfig
    unrecorded: DictConfig
    progress: bool
    recording: Path | None
    """The rerun file a recorded evaluation writes, if it writes one."""

    @classmethod
    def of(cls, cfg: DictConfig) -> EvaluationPlan:
        """The evaluations of a pipeline config."""
        unrecorded = OmegaConf.merge(cfg.eval, {"rerun": None, "lerobot": None})
        rerun = cfg.eval.rerun
        recording = Path(rerun) if rerun and describe_target(rerun) == "file" else None
        settings = (frozen(cfg.eval), frozen(unrecorded))
        return cls(frozen(cfg.env), *settings, cfg.progress, recording)

    def settings(self, *, record: bool) -> DictConfig:
        """The ``eval`` settings, recording as they say or not at all."""
        return self.recorded if record else self.unrecorded

    @property
    def records(self) -> bool:
        """Whether the settings record anything (``eval.rerun`` or ``eval.lerobot``)."""
        return bool(self.recorded.rerun or self.recorded.lerobot)


def shipped_specs(names: list[str] | None) -> dict[str, str]:
    """The shipped policies the comparison lists, as row names and driver specs
    (``pretrained:NAME``): those ``names`` (null: every shipped one).

    Raises:
        ValueError: a name that is not shipped (with those that are).

    Example:
        >>> shipped_specs([])
        {}
    """
    names = list(shipped_policies()) if names is None else [str(name) for name in names]
    specs = [f"{PRETRAINED}{name.removeprefix(PRETRAINED)}" for name in names]
    for spec in specs:
        pretrained_path(spec)  # an unknown name fails here, before any stage
    return {spec: spec for spec in specs}


@dataclass(frozen=True)
class RunPlan:
    """Everything one run of the main job does, resolved from its config by :func:`plan_run`."""

    config: DictConfig
    """The run's settings, as saved beside its outputs."""
    output_dir: Path
    capabilities: Capabilities
    demonstrators: Demonstrators
    record: RecordPlan
    clone: tuple[CloneRound, ...]
    """The clone rounds, in order: the last one's policy is the clone."""
    ppo: DictConfig
    """PPO fine-tuning of the clone."""
    eval: EvaluationPlan
    references: tuple[str, ...]
    """The reference drivers' specs the comparison lists (those the endpoint can drive)."""
    shipped: tuple[str, ...]
    """The shipped policies' specs the comparison lists."""


def plan_run(cfg: DictConfig) -> RunPlan:
    """The plan of ``cfg`` (a :class:`~oasis_torchrl.config.DemoConfig`); the endpoint is asked
    what it sends here, once.

    Example:
        >>> plan = plan_run(load_config("demo", ["output_dir=/tmp/d"]))
        >>> plan.demonstrators.source, len(plan.clone), plan.ppo.init_from, plan.ppo.eval.final
        ('autopilot', 2, '/tmp/d/bc/round_1/policy', False)
        >>> plan.references
        ('autopilot', 'constant:throttle=1.0,steering=0.0')
    """
    shipped = tuple(shipped_specs(cfg.eval.get("pretrained")))  # an unknown name fails first
    capabilities = env_capabilities(cfg.env)
    demonstrators = Demonstrators.of(cfg, capabilities)
    record = RecordPlan.of(cfg, demonstrators)
    rounds = clone_rounds(cfg, record, demonstrators)
    # The eval stage evaluates the kept policy on the same prompts and seeds right after:
    # PPO's own final evaluation would repeat it.
    ppo = OmegaConf.merge(ppo_config(cfg, rounds[-1].policy), {"eval": {"final": False}})
    references = [str(spec) for spec in cfg.eval.get(REFERENCE_KEY, [])]
    if not capabilities.ground_truth:  # the autopilot drives with ground truth
        references = [spec for spec in references if spec != AUTOPILOT]
    return RunPlan(
        frozen(cfg),
        Path(cfg.output_dir),
        capabilities,
        demonstrators,
        record,
        rounds,
        frozen(ppo),
        EvaluationPlan.of(cfg),
        tuple(dict.fromkeys(references)),
        shipped,
    )
