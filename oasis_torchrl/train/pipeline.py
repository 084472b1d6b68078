"""The main job in one call: record -> behaviour cloning -> PPO fine-tuning -> evaluation.

1. ``record``: autopilot demonstrations as a LeRobot dataset (one row per frame), with noise
   injected into the executed actions (:mod:`oasis_torchrl.train.demonstrations`);
2. ``bc``: behaviour cloning on it (the ``bc`` stage settings,
   :class:`~oasis_torchrl.config.BCSettings`),
   then ``dagger.rounds`` DAgger rounds: the clone drives ``dagger.episodes`` episodes labelled
   by the autopilot and is fine-tuned for ``dagger.steps`` on them and all the earlier data
   (:func:`dagger_data`; the demonstrations themselves are never written to);
3. ``ppo``: PPO fine-tuning warm-started from the cloned policy (the ``ppo`` stage settings,
   :class:`~oasis_torchrl.config.PPOSettings`, with the shared ``env``);
4. ``eval``: the reference drivers, the shipped policies (``eval.pretrained``, by default every
   one the package ships), the cloned and the fine-tuned policy on the same fixed prompts and
   seeds (a fine-tuning that did not beat the clone is "not kept": no row of its own); the
   best learned policy's episodes go to rerun (``eval.rerun``, by default
   ``<output_dir>/eval.rrd``) and to a LeRobot dataset if ``eval.lerobot`` is set
   (:mod:`oasis_torchrl.train.main_evaluation`).

On an endpoint that sends frames only (the hosted service, a hosted-like server) there is no
autopilot: the demonstrations come from ``record.source`` (a saved or served policy, a LeRobot
dataset of a person's drives, or a folder of recordings in the reference format, imported), the
DAgger rounds are labelled by ``dagger.labeller`` (by default the demonstrating policy; none
after a dataset), behaviour cloning has no auxiliary loss, PPO a camera-only critic and the
frames-only motion reward, and the comparison reports returns (:class:`Demonstrators`). Without a
source it stops at once, saying what to pass.

Every stage shows a progress bar. A stage whose output already exists is reused (delete the
folder to redo it), so re-running after an interruption continues where it stopped. Outputs under
``output_dir``: ``demos/`` (dataset), ``bc/round_<k>/policy/``, ``ppo/policy/`` (LeRobot policy
folders), ``bc/round_<k>/dagger/`` and ``bc/round_<k>/dataset/`` (round k's episodes, and the
data it cloned: the demonstrations and rounds 1 to k), ``ppo/checkpoints/`` (``latest.pt``, the
training state; ``best.pt``, the policy kept when PPO's evaluations select one), ``eval.rrd``,
``summary.json`` (paths, evaluations with their episodes, seconds per stage) and
``comparison.png`` (the evaluations as bars; the same comparison as a text table is
:meth:`PipelineResult.table`). Config: :class:`~oasis_torchrl.config.DemoConfig`.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.atomic import written_whole
from oasis_torchrl.config import load_config, save_config
from oasis_torchrl.config.env import AUTO
from oasis_torchrl.drivers import AUTOPILOT, Driver, load_driver, pretrained_path
from oasis_torchrl.drivers.late_reaction import LateReactionAutopilot
from oasis_torchrl.envs.capabilities import env_capabilities
from oasis_torchrl.train.cards import hours, load_card
from oasis_torchrl.train.comparison import PolicyRow, best_learned, format_table, plot_comparison
from oasis_torchrl.train.demonstrations import ActionNoise, record_demonstrations
from oasis_torchrl.train.main_evaluation import (
    comparison_rows,
    evaluate_and_record_best,
    shipped_specs,
)
from oasis_torchrl.train.stage_seconds import STAGE_SECONDS, add_stage_seconds

logger = logging.getLogger(__name__)

REFERENCE_KEY = "reference"
FINE_TUNE = "bc+ppo"
SHARED_EVAL_KEYS = ("prompts", "seeds", "max_steps")
"""``eval`` keys PPO's own evaluations take from the pipeline's (how many and how often stay
the ``ppo.eval`` settings')."""


@dataclass
class PipelineResult:
    """Where the pipeline's outputs are, and the evaluation of every policy.

    Example:
        >>> result = run_pipeline(load_config("demo"))  # doctest: +SKIP
        >>> result.to_dict()["paths"]["recording"]  # doctest: +SKIP
        'outputs/demo/eval.rrd'
    """

    dataset: Path
    bc_policy: Path
    ppo_policy: Path
    ppo_checkpoint: Path
    recording: Path | None
    summary_path: Path
    plot_path: Path
    evaluations: dict[str, dict[str, Any]] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    fine_tune_kept: bool = True
    """Whether PPO fine-tuning beat the clone (else its row reads "not kept")."""
    cards: dict[str, dict[str, Any] | None] = field(default_factory=dict)
    """The evaluated shipped policies' card facts by row name (None: a policy without one)."""

    def rows(self) -> list[PolicyRow]:
        """The evaluations compared with the autopilot and the best constant action; a
        fine-tuning not kept is a "not kept" row."""
        rows = comparison_rows(self.evaluations, list(self.cards))
        return rows if self.fine_tune_kept else [*rows, PolicyRow.not_kept(FINE_TUNE)]

    def table(self) -> str:
        """The comparison as a text table, what learning took (with shipped policies), and where
        the files are."""
        total = sum(self.seconds.values())
        learned = self.learning_line()
        return (
            f"{format_table(self.rows())}\n"
            + (f"{learned}\n" if learned else "")
            + f"\n{total / 60:.1f} min; summary {self.summary_path}, plot {self.plot_path}"
        )

    def learning_line(self) -> str | None:
        """One plain line: what this run learned in its minutes, and what the shipped policies
        took to train (from their cards); None without shipped policies.

        Example:
            >>> result = PipelineResult(*[Path()] * 7, seconds={"bc": 600.0},
            ...     evaluations={"constant:throttle=1.0": {"mean_distance": 100.0,
            ...     "collision_rate": 1.0, "episodes": 16}, "bc": {"mean_distance": 90.0,
            ...     "collision_rate": 0.5, "episodes": 16}},
            ...     cards={"pretrained:ppo-scratch": {"budget": "204,800 env steps",
            ...     "wall_seconds": 18000.0, "machine": "2 cores"}})
            >>> print(result.learning_line())
            This run learned in 10 min: bc drives 0.90x the best constant. The shipped policies \
took: pretrained:ppo-scratch 204,800 env steps, 5.0 h on 2 cores.
        """
        if not self.cards:
            return None
        own = [row for row in self.rows() if row.kind == "learned"]
        best = best_learned(own)
        minutes = sum(self.seconds.values()) / 60
        learned = (
            f"{best.name} drives {best.vs_constant:.2f}x the best constant"
            if best is not None and best.vs_constant is not None
            else "no comparable policy"
        )
        took = "; ".join(
            f"{name} {card['budget']}, {hours(card['wall_seconds'])} on {card['machine']}"
            if card
            else f"{name} (no card)"
            for name, card in self.cards.items()
        )
        return (
            f"This run learned in {minutes:.0f} min: {learned}. The shipped policies took: {took}."
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``paths`` (str or None), ``evaluations`` and ``seconds`` per stage."""
        paths = {
            "dataset": self.dataset,
            "bc_policy": self.bc_policy,
            "ppo_policy": self.ppo_policy,
            "ppo_checkpoint": self.ppo_checkpoint,
            "recording": self.recording,
            "summary": self.summary_path,
            "plot": self.plot_path,
        }
        return {
            "paths": {name: None if path is None else str(path) for name, path in paths.items()},
            "evaluations": self.evaluations,
            "fine_tune_kept": self.fine_tune_kept,
            "seconds": self.seconds,
        }


@contextmanager
def timed_stage(
    seconds: dict[str, float], stage: str, totals: Path | None = None
) -> Iterator[None]:
    """Log the start of ``stage`` and put its wall time (seconds, 0.1 s) in ``seconds``; with
    ``totals`` (a JSON file), also add it to the stage's total there, even if the stage stops
    half way.

    Example:
        >>> seconds = {}
        >>> with timed_stage(seconds, "record"):
        ...     pass
        >>> list(seconds)
        ['record']
    """
    logger.info("pipeline stage %s", stage)
    started = time.perf_counter()
    try:
        yield
    finally:
        elapsed = round(time.perf_counter() - started, 1)
        seconds[stage] = elapsed
        if totals is not None:
            add_stage_seconds(totals, stage, elapsed)


@dataclass(frozen=True)
class Demonstrators:
    """Who demonstrates and who labels the DAgger rounds, for what the endpoint sends.

    Example:
        >>> Demonstrators.of(load_config("demo"))
        Demonstrators(source='autopilot', labeller='autopilot', ground_truth=True)
        >>> Demonstrators.of(load_config("demo", ["env.server.hosted=true"]))
        Traceback (most recent call last):
        ...
        ValueError: the demonstrations need a source: the hosted-like embedded server sends ...
    """

    source: str
    """A driver spec (recorded from), a LeRobot dataset folder or a recordings folder."""
    labeller: str | None
    """The DAgger rounds' labeller (a driver spec); None: no rounds."""
    ground_truth: bool

    @classmethod
    def of(cls, cfg: DictConfig) -> Demonstrators:
        """Resolve ``record.source`` and ``dagger.labeller`` (``auto``: the autopilot where the
        endpoint sends ground truth; elsewhere the source must be given)."""
        found = env_capabilities(cfg.env)
        source, labeller = str(cfg.record.source), str(cfg.dagger.labeller)
        if source == AUTO and found.frames_only:
            raise ValueError(
                f"the demonstrations need a source: {found.endpoint} sends frames only (no "
                "autopilot); pass record.source=<a policy folder, checkpoint or "
                "grpc://host:port>, or a LeRobot dataset of a person's drives (lerobot-record "
                "with the keyboard teleoperators), or a folder of recordings in the reference "
                "format (episode_*/manifest.jsonl)"
            )
        source = AUTOPILOT if source == AUTO else source
        recorded = _is_dataset(source) or _is_recordings(source)
        if labeller == AUTO:
            labeller = AUTOPILOT if found.ground_truth else None if recorded else source
        for name, spec in (("record.source", source), ("dagger.labeller", labeller)):
            if spec == AUTOPILOT:
                found.require(f"{name}=autopilot", f"pass a policy or a person's drives as {name}")
        return cls(source, labeller, found.ground_truth)

    def driver(self) -> Driver | None:
        """The demonstrating driver (None: the autopilot, or demonstrations already recorded)."""
        if self.source == AUTOPILOT or _is_dataset(self.source) or _is_recordings(self.source):
            return None
        return load_driver(self.source)


def _is_dataset(source: str) -> bool:
    return (Path(source) / "meta" / "info.json").is_file()


def _is_recordings(source: str) -> bool:
    return any(Path(source).glob("episode_*/manifest.jsonl"))


def demonstrations(cfg: DictConfig, root: Path) -> Path:
    """The demonstrations: ``record.source``'s dataset, its recordings imported into ``root``,
    or ``cfg.record.episodes`` noisy-execution episodes recorded into ``root`` (labelled by the
    autopilot or the source policy; a complete earlier recording is reused). Written whole or
    not at all (:func:`~oasis_torchrl.atomic.written_whole`).

    Example:
        >>> demonstrations(load_config("demo"), Path("outputs/demo/demos"))  # doctest: +SKIP
    """
    who = Demonstrators.of(cfg)
    if _is_dataset(who.source):
        logger.info("demonstrations: the dataset %s", who.source)
        return Path(who.source)
    info = root / "meta" / "info.json"
    if info.exists():
        episodes = json.loads(info.read_text())["total_episodes"]
        if episodes >= cfg.record.episodes:
            logger.info("reusing %s (%d episodes)", root, episodes)
            return root
        raise FileExistsError(
            f"{root} holds {episodes} of {cfg.record.episodes} episodes; delete it"
        )
    with written_whole(root) as partial:  # a stop half way records them again next run
        if _is_recordings(who.source):
            from oasis_torchrl.data.importer import import_recordings

            report = import_recordings(who.source, partial, image_size=tuple(cfg.env.image_size))
            logger.info("imported %d recordings from %s", len(report.imported), who.source)
        else:
            reaction, seed = cfg.record.late_reaction, cfg.record.seed
            late = reaction is not None and who.source == AUTOPILOT
            record_demonstrations(
                cfg.env,
                partial,
                episodes=cfg.record.episodes,
                seed=seed,
                noise=ActionNoise(**cfg.record.noise),
                learner=LateReactionAutopilot(tuple(reaction), seed=seed) if late else None,
                labeller=who.driver(),
                progress=cfg.progress,
            )
    return root


def bc_config(cfg: DictConfig, dataset: Path, round_: int) -> DictConfig:
    """The BC config of clone round ``round_`` (0: from scratch; k: DAgger round k, which
    fine-tunes the previous clone).

    Example:
        >>> bc = bc_config(load_config("demo", ["output_dir=/tmp/d"]), Path("/tmp/d/x"), 1)
        >>> bc.output_dir, bc.init_from, bc.dataset.root, bc.train.steps
        ('/tmp/d/bc/round_1', '/tmp/d/bc/round_0/policy', '/tmp/d/x', 500)
    """
    values: dict[str, Any] = {
        "seed": cfg.seed + round_,
        "progress": cfg.progress,
        "output_dir": str(round_folder(cfg, round_)),
        "dataset": {"root": str(dataset)},
        "eval": {"episodes": 0},
        "policy": {"image_size": list(cfg.env.image_size), "front_crop": cfg.env.front_crop},
    }
    if round_:
        values["init_from"] = str(previous_clone(cfg, round_))
        values["train"] = {"steps": cfg.dagger.steps}
    if not env_capabilities(cfg.env).ground_truth:  # no privileged state in the demonstrations
        values["policy"]["aux_weight"] = 0.0
    return OmegaConf.merge(load_config("bc"), _plain(cfg.bc), values)


def round_folder(cfg: DictConfig, round_: int) -> Path:
    """Where clone round ``round_`` writes (its config, logs and ``policy/``).

    Example:
        >>> round_folder(load_config("demo", ["output_dir=/tmp/d"]), 2)
        PosixPath('/tmp/d/bc/round_2')
    """
    return Path(cfg.output_dir) / "bc" / f"round_{round_}"


def previous_clone(cfg: DictConfig, round_: int) -> Path:
    """The policy folder of the clone before round ``round_``: the one that drives its DAgger
    episodes.

    Example:
        >>> previous_clone(load_config("demo", ["output_dir=/tmp/d"]), 2)
        PosixPath('/tmp/d/bc/round_1/policy')
    """
    return round_folder(cfg, round_ - 1) / "policy"


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


def round_data(cfg: DictConfig, dataset: Path, round_: int) -> Path:
    """The data clone round ``round_`` trains on: the demonstrations ``dataset`` (round 0), or
    those and DAgger rounds 1 to ``round_`` combined (``bc/round_<k>/dataset``).

    Example:
        >>> round_data(load_config("demo", ["output_dir=/tmp/d"]), Path("/tmp/d/demos"), 2)
        PosixPath('/tmp/d/bc/round_2/dataset')
    """
    return round_folder(cfg, round_) / "dataset" if round_ else dataset


def dagger_data(cfg: DictConfig, dataset: Path, round_: int, labeller: str) -> Path:
    """Record DAgger round ``round_``'s episodes (the previous clone drives, ``labeller`` labels)
    into ``bc/round_<k>/dagger``, and combine them with the previous round's data into
    :func:`round_data`; either folder is reused when it exists.

    Each is written whole or not at all (:func:`~oasis_torchrl.atomic.written_whole`): a stop
    while the round records loses only the round's unfinished episodes, which the next run
    records again from the start, and the demonstrations, a person's dataset among them, are
    only read.

    Example:
        >>> cfg = load_config("demo")
        >>> dagger_data(cfg, Path("outputs/demo/demos"), 1, "autopilot")  # doctest: +SKIP
        PosixPath('outputs/demo/bc/round_1/dataset')
    """
    from oasis_torchrl.data.combine import combine_datasets

    episodes, data = round_folder(cfg, round_) / "dagger", round_data(cfg, dataset, round_)
    if not episodes.exists():
        with written_whole(episodes) as partial:
            record_demonstrations(
                cfg.env,
                partial,
                episodes=cfg.dagger.episodes,
                seed=cfg.record.seed + 1000 * round_,
                noise=ActionNoise(**cfg.dagger.noise),
                learner=load_driver(str(previous_clone(cfg, round_))),
                labeller=None if labeller == AUTOPILOT else load_driver(labeller),
                progress=cfg.progress,
            )
    if not data.exists():
        combine_datasets([round_data(cfg, dataset, round_ - 1), episodes], data)
    return data


def clone(cfg: DictConfig, dataset: Path) -> Path:
    """Behaviour cloning, then the DAgger rounds; the final policy folder (stages reused).

    Example:
        >>> clone(load_config("demo"), Path("outputs/demo/demos"))  # doctest: +SKIP
        PosixPath('outputs/demo/bc/round_0/policy')
    """
    from oasis_torchrl.train.bc import PARTIAL_POLICY, TRAINING_STATE, train_bc

    labeller = Demonstrators.of(cfg).labeller
    rounds = cfg.dagger.rounds if labeller is not None else 0
    if rounds < cfg.dagger.rounds:
        logger.info("no DAgger rounds: demonstrations from a dataset have no labeller")
    policy = Path()
    for round_ in range(rounds + 1):
        policy = round_folder(cfg, round_) / "policy"
        if (policy / "model.safetensors").exists():
            logger.info("reusing %s", policy)
            continue
        data = dagger_data(cfg, dataset, round_, labeller) if round_ else dataset
        bc_cfg = bc_config(cfg, data, round_)
        if (Path(bc_cfg.output_dir) / PARTIAL_POLICY / TRAINING_STATE).exists():
            bc_cfg.resume = "latest"  # its cloning stopped half way
        train_bc(bc_cfg)
    return policy


@dataclass
class PPOStage:
    """A finished (or reused) PPO stage: its policy folder, the checkpoint of that policy, the
    env steps it trained for (0: a fine-tuning kept its warm start) and the evaluation history.

    Example:
        >>> run_ppo(ppo_config(load_config("demo"), None)).history  # doctest: +SKIP
    """

    policy_dir: Path
    checkpoint: Path
    policy_frames: int
    history: list[dict[str, float]]


def run_ppo(ppo_cfg: DictConfig) -> PPOStage:
    """Train a PPO stage, resume it, or reuse it when its policy folder exists.

    Example:
        >>> stage = run_ppo(ppo_config(load_config("demo"), None))  # doctest: +SKIP
    """
    from oasis_torchrl.models.checkpoint import BEST, LATEST, load_checkpoint
    from oasis_torchrl.train.ppo import train_ppo

    out = Path(ppo_cfg.output_dir)
    policy, checkpoints = out / "policy", out / "checkpoints"
    if (policy / "model.safetensors").exists():
        logger.info("reusing %s", policy)
        history = load_checkpoint(checkpoints / LATEST)["history"]
    else:
        if (checkpoints / LATEST).exists():
            ppo_cfg.resume = "latest"
        result = train_ppo(ppo_cfg)
        policy, history = result.policy_dir or policy, result.history
    # The policy a stage leaves: the selection's choice (best.pt) if it made one, else the last.
    kept = checkpoints / BEST if (checkpoints / BEST).exists() else checkpoints / LATEST
    return PPOStage(policy, kept, load_checkpoint(kept)["frames"], history)


def run_pipeline(cfg: DictConfig) -> PipelineResult:
    """Run record -> BC -> PPO fine-tuning -> evaluation as ``cfg`` (a
    :class:`~oasis_torchrl.config.DemoConfig`) says.

    Example:
        >>> result = run_pipeline(load_config("demo"))  # doctest: +SKIP
        >>> result.evaluations["bc+ppo"]["mean_distance"]  # doctest: +SKIP
    """
    from oasis_torchrl.viz.recording import describe_target

    shipped = shipped_specs(cfg.eval.get("pretrained"))  # an unknown name fails first
    out = Path(cfg.output_dir)
    save_config(cfg, out / "config.yaml")
    seconds: dict[str, float] = {}
    totals = out / STAGE_SECONDS
    with timed_stage(seconds, "record", totals):
        dataset = demonstrations(cfg, out / "demos")
    with timed_stage(seconds, "bc", totals):
        bc_policy = clone(cfg, dataset)
    with timed_stage(seconds, "ppo", totals):
        # The eval stage evaluates the kept policy on the same prompts and seeds right after:
        # PPO's own final evaluation would repeat it.
        ppo = run_ppo(OmegaConf.merge(ppo_config(cfg, bc_policy), {"eval": {"final": False}}))
    references = {str(spec): str(spec) for spec in cfg.eval.get(REFERENCE_KEY, [])}
    if not env_capabilities(cfg.env).ground_truth:  # the autopilot drives with ground truth
        references.pop(AUTOPILOT, None)
    policies: dict[str, Any] = {**references, **shipped, "bc": str(bc_policy)}
    # A fine-tuning that kept its warm start left the clone: its row reads "not kept".
    kept = ppo.policy_frames > 0
    if kept:
        policies[FINE_TUNE] = str(ppo.policy_dir)
    rerun = cfg.eval.rerun
    recording = Path(rerun) if rerun and describe_target(rerun) == "file" else None
    cards = {name: load_card(pretrained_path(name)) for name in shipped}
    with timed_stage(seconds, "eval"):
        evaluations = evaluate_and_record_best(cfg, policies, list(shipped))
        result = PipelineResult(
            dataset,
            bc_policy,
            ppo.policy_dir,
            ppo.checkpoint,
            recording,
            out / "summary.json",
            out / "comparison.png",
            evaluations,
            seconds,
            kept,
            cards,
        )
    result.summary_path.write_text(json.dumps(result.to_dict(), indent=2))
    seeds = ", ".join(str(seed) for seed in cfg.eval.seeds)
    title = (
        f"{', '.join(cfg.eval.prompts)}: {cfg.eval.episodes} episodes of up to "
        f"{cfg.eval.max_steps} steps per seed ({seeds})"
    )
    plot_comparison(result.rows(), result.plot_path, title)
    logger.info("pipeline done in %.0f s; summary: %s", sum(seconds.values()), out / "summary.json")
    return result
