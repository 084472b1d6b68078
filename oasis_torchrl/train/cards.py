"""Shipping a trained policy: its folder copied into the shipped policies with a model card.

:func:`ship_policy` reads the training run around a policy folder (:class:`TrainingRun`: a PPO
run, ``<run>/policy``, or a main-job run's clone, ``<run>/bc/round_<k>/policy``), evaluates the
policy beside the best constant action on the report's prompts and seeds and on each held-out
scene and seed, and writes ``README.md`` (the command that trained it, the commit, wall time and
machine, the figures, the curve), ``curve.png`` and ``card.json`` (the same facts for programs:
the main job reads what each shipped policy took to train from it). Distances come from the
embedded server's ground truth: a card cannot be written against an endpoint that sends frames
only.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import platform
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.atomic import written_whole
from oasis_torchrl.config import load_config
from oasis_torchrl.config.presets import preset_names
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.drivers.pretrained import POLICY_FILES, policies_folder
from oasis_torchrl.evaluation import EvalReport, Evaluator
from oasis_torchrl.train.stage_seconds import STAGE_SECONDS

logger = logging.getLogger(__name__)

CARD = "README.md"
CARD_DATA = "card.json"
CURVE = "curve.png"
RUN_ONLY_KEYS = ("output_dir", "resume", "progress")
"""Settings that say where and how a run went, not what it trained: ignored when a run's saved
settings are matched to a preset."""
CAPABILITY_KEYS = ("privileged_critic", "loss.aux_coeff")
"""Settings a PPO run saves filled in from what its endpoint sends, where a preset leaves them
null."""


def missing(path: Path) -> Path:
    """``path`` itself when it exists.

    Raises:
        FileNotFoundError: one line naming the missing file.

    Example:
        >>> missing(Path("nowhere/config.yaml"))
        Traceback (most recent call last):
        ...
        FileNotFoundError: the run lacks nowhere/config.yaml, which the card needs
    """
    if not path.exists():
        raise FileNotFoundError(f"the run lacks {path}, which the card needs")
    return path


@dataclass
class TrainingRun:
    """The run that trained a policy folder: its kind, folder, settings, wall time and curve.

    Example:
        >>> TrainingRun.of(Path("nowhere/policy"))
        Traceback (most recent call last):
        ...
        FileNotFoundError: the run lacks nowhere/policy/config.json, which the card needs
    """

    kind: str
    """``ppo`` (``train ppo``) or ``demo`` (the main job's clone)."""
    root: Path
    policy: Path
    settings: DictConfig
    wall_seconds: float | None
    budget: str
    """What it trained on, in words (env steps, demonstrations and rounds)."""
    curve: dict[str, list[tuple[float, float]]]
    """Named series of (x, y) points."""
    curve_axes: tuple[str, str]
    kept_steps: int | None = None
    """The env steps of the policy a PPO run kept, where its selection evaluations kept an
    earlier one than the last (None: the last)."""

    @classmethod
    def of(cls, policy: Path) -> TrainingRun:
        """Read the run around ``policy``.

        Raises:
            FileNotFoundError: a file the card needs is missing (named).
        """
        policy = Path(policy)
        for name in POLICY_FILES:
            missing(policy / name)
        if policy.parent.parent.name == "bc":
            return cls._clone(policy, policy.parents[2])
        return cls._ppo(policy, policy.parent)

    @classmethod
    def _ppo(cls, policy: Path, root: Path) -> TrainingRun:
        from oasis_torchrl.models.checkpoint import BEST, LATEST, load_checkpoint

        settings = OmegaConf.load(missing(root / "config.yaml"))
        state = load_checkpoint(missing(root / "checkpoints" / LATEST))
        curve: dict[str, list[tuple[float, float]]] = {}  # a series per evaluated seeds
        for entry in state["history"]:  # the final evaluation too, at its policy's steps
            seeds = entry["seeds"]
            label = f"seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}"
            point = (entry["policy_frames"], entry["mean_distance"])
            curve.setdefault(f"evaluations on {label}", []).append(point)
        best = root / "checkpoints" / BEST  # the policy exported when the selection chose one
        kept_steps = load_checkpoint(best)["frames"] if best.exists() else state["frames"]
        return cls(
            "ppo",
            root,
            policy,
            settings,
            state.get("wall_seconds"),
            f"{state['frames']:,} env steps",
            {name: sorted(points) for name, points in curve.items()},
            ("env steps", "mean distance before collision (m)"),
            None if kept_steps == state["frames"] else kept_steps,
        )

    @classmethod
    def _clone(cls, policy: Path, root: Path) -> TrainingRun:
        settings = OmegaConf.load(missing(root / "config.yaml"))
        totals = root / STAGE_SECONDS  # every run of the folder, stopped ones included
        if totals.exists():
            seconds = json.loads(totals.read_text())
        else:  # a run from before the totals: its last run's times
            seconds = json.loads(missing(root / "summary.json").read_text())["seconds"]
        rounds = sorted((root / "bc").glob("round_*"), key=lambda p: int(p.name.split("_")[1]))
        rounds = rounds[: rounds.index(policy.parent) + 1]
        curve, offset = {}, 0.0
        for folder in rounds:
            losses = read_scalars(folder / "logs", "bc/loss")
            curve[folder.name.replace("_", " ")] = [(offset + x, y) for x, y in losses]
            offset += losses[-1][0] if losses else 0.0
        demonstrations = settings.record.episodes
        budget = f"{demonstrations} demonstrations, {len(rounds) - 1} DAgger rounds"
        return cls(
            "demo",
            root,
            policy,
            settings,
            seconds.get("record", 0.0) + seconds.get("bc", 0.0),
            budget,
            curve,
            ("gradient steps", "behaviour-cloning loss"),
        )

    def settings_yaml(self) -> str:
        """The run's saved settings as YAML, its folder written ``<run>``: where it ran (a path
        of the machine that trained it) is not part of the recipe."""
        return OmegaConf.to_yaml(self.settings).replace(str(self.root), "<run>")

    def command(self) -> str:
        """The command that retrains it: its preset's when its saved settings are the preset's,
        else the saved settings themselves."""
        verb = "train ppo" if self.kind == "ppo" else "demo"
        preset = matching_preset(self.kind, self.settings)
        source = preset or str(self.root / "config.yaml")
        return f"oasis-torchrl {verb} --config {source}"


def read_scalars(logs: Path, name: str) -> list[tuple[float, float]]:
    """The ``(step, value)`` rows a TorchRL CSV logger wrote for scalar ``name`` under ``logs``.

    Raises:
        FileNotFoundError: no such CSV file (named).

    Example:
        >>> import tempfile
        >>> logs = Path(tempfile.mkdtemp())
        >>> (logs / "bc" / "scalars" / "bc").mkdir(parents=True)
        >>> _ = (logs / "bc" / "scalars" / "bc" / "loss.csv").write_text("50,1.5\\n100,0.5\\n")
        >>> read_scalars(logs, "bc/loss")
        [(50.0, 1.5), (100.0, 0.5)]
    """
    files = sorted(logs.glob(f"*/scalars/{name}.csv"))
    if not files:
        missing(logs / "<experiment>" / "scalars" / f"{name}.csv")
    with files[0].open() as file:
        return [(float(step), float(value)) for step, value in csv.reader(file)]


def matching_preset(kind: str, settings: DictConfig) -> str | None:
    """The preset whose settings a run's saved ones are (but where and how it ran), if any.

    Example:
        >>> matching_preset("ppo", load_config("ppo", file="ppo_scratch"))
        'ppo_scratch'
    """

    def comparable(cfg: DictConfig, preset: DictConfig) -> dict[str, Any]:
        cfg = cfg.copy()
        for key in CAPABILITY_KEYS:
            if OmegaConf.select(preset, key, default=0) is None:
                OmegaConf.update(cfg, key, None)
        # As saved: a run's YAML holds lists where a loaded preset holds tuples.
        saved = OmegaConf.to_container(OmegaConf.create(OmegaConf.to_yaml(cfg)))
        return {key: value for key, value in saved.items() if key not in RUN_ONLY_KEYS}

    # Paths made from the output folder (the main job's eval.rerun) follow the run's.
    where = [("output_dir", settings.output_dir)]
    for name in preset_names():
        try:
            preset = load_config(kind, file=name, values=where)
        except ValueError:  # a preset of another command
            continue
        if comparable(settings, preset) == comparable(preset, preset):
            return name
    return None


def machine() -> str:
    """This machine in words: cores and CPU model.

    Example:
        >>> "cores" in machine()
        True
    """
    model = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        names = [line for line in cpuinfo.read_text().splitlines() if line.startswith("model name")]
        model = names[0].split(":", 1)[1].strip() if names else model
    return f"{os.cpu_count()} cores, {model}"


def source_commit() -> str | None:
    """The commit of the source tree this package runs from (None: not a git checkout)."""
    root = Path(__file__).resolve().parents[2]
    try:
        done = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip()


@dataclass(frozen=True)
class SceneFigures:
    """A policy beside the baseline on one scene (or the report's prompts together).

    Example:
        >>> SceneFigures("urban", [1000], 16, 300.0, 10.0, 0.1, 150.0, 0.9).ratio
        2.0
    """

    scene: str
    seeds: list[int]
    episodes: int
    distance: float
    stderr: float
    collision_rate: float
    baseline_distance: float
    baseline_collision_rate: float

    @property
    def ratio(self) -> float:
        """The policy's mean distance over the baseline's."""
        return self.distance / self.baseline_distance if self.baseline_distance else float("nan")

    @classmethod
    def of(
        cls, scene: str, seeds: Sequence[int], policy: EvalReport, baseline: EvalReport
    ) -> SceneFigures:
        """The figures of two reports of the same episodes."""
        from oasis_torchrl.train.comparison import distance_stderr

        return cls(
            scene,
            list(seeds),
            len(policy.episodes),
            policy.mean_distance,
            distance_stderr(policy.to_dict()),
            policy.collision_rate,
            baseline.mean_distance,
            baseline.collision_rate,
        )


def evaluate_card(cfg: DictConfig, policy: Path) -> list[SceneFigures]:
    """The policy and ``cfg.baseline`` on the report's prompts and seeds (one row), then on
    each held-out scene over the held-out seeds (a row each).

    Raises:
        ValueError: the endpoint sends frames only (no distance to report).
    """
    rows = []
    sets = [
        ("report", list(cfg.prompts), list(cfg.seeds)),
        ("held out", list(cfg.held_out_prompts), list(cfg.held_out_seeds)),
    ]
    for label, prompts, seeds in sets:
        eval_cfg = OmegaConf.create(
            {
                "prompts": prompts,
                "seeds": seeds,
                "episodes": cfg.episodes,
                "max_steps": cfg.max_steps,
            }
        )
        policy_report, baseline_report = (
            _evaluate(cfg.env, eval_cfg, spec, cfg.progress) for spec in (str(policy), cfg.baseline)
        )
        if label == "report":
            rows.append(SceneFigures.of(", ".join(prompts), seeds, policy_report, baseline_report))
            continue
        baselines = baseline_report.per_prompt()
        for prompt, part in policy_report.per_prompt().items():
            rows.append(SceneFigures.of(prompt, seeds, part, baselines[prompt]))
    return rows


def _evaluate(env: DictConfig, eval_cfg: DictConfig, spec: str, progress: bool) -> EvalReport:
    driver = load_driver(spec)
    with Evaluator.for_driver(env, eval_cfg, driver, progress=progress) as evaluator:
        if evaluator.frames_only:
            raise ValueError(
                "a card reports distances, which need the embedded server's ground truth: "
                "evaluate on the embedded server (not a frames-only endpoint)"
            )
        return evaluator.evaluate(driver)


def ship_policy(cfg: DictConfig) -> Path:
    """Evaluate the run's policy and write it, with its card, into the shipped policies as
    ``cfg.name`` (:class:`~oasis_torchrl.config.pretrained.ShipConfig`); the folder appears
    only once complete.

    Raises:
        FileNotFoundError: the run lacks a file the card needs (named).
        FileExistsError: a shipped policy of that name exists.
        ValueError: the endpoint sends frames only.

    Example:
        >>> from oasis_torchrl.config.pretrained import ShipConfig
        >>> ship_policy(load_config(ShipConfig, ["policy=run/policy", "name=x"]))  # doctest: +SKIP
    """
    run = TrainingRun.of(Path(cfg.policy))
    shipped = Path(cfg.output) if cfg.output else policies_folder()
    target = shipped / cfg.name
    if target.exists():
        raise FileExistsError(f"{target} exists: delete it to ship {cfg.name} again")
    figures = evaluate_card(cfg, run.policy)
    with written_whole(target) as partial:
        shutil.copytree(run.policy, partial)
        _write_card(partial, run, cfg, figures)
    logger.info("shipped %s: %s", cfg.name, target)
    return target


def _write_card(folder: Path, run: TrainingRun, cfg: DictConfig, figures: list[Any]) -> None:
    """The card's facts, curve and text into the policy ``folder`` being shipped."""
    facts = {
        "name": cfg.name,
        "kind": run.kind,
        "command": run.command(),
        "commit": cfg.commit or source_commit(),
        "wall_seconds": run.wall_seconds,
        "machine": cfg.machine or machine(),
        "budget": run.budget,
        "kept_steps": run.kept_steps,
        "training_prompts": list(run.settings.env.prompts),
        "front_crop": run.settings.env.get("front_crop"),
        "baseline": cfg.baseline,
        "figures": [{**asdict(row), "ratio": row.ratio} for row in figures],
    }
    (folder / CARD_DATA).write_text(json.dumps(facts, indent=2))
    plot_curve(run, folder / CURVE, cfg.name)
    (folder / CARD).write_text(card_text(facts, run.settings_yaml()))


def plot_curve(run: TrainingRun, path: Path, name: str) -> Path:
    """The run's training curve as a PNG."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(7, 3.5), layout="constrained")
    axes = figure.add_subplot()
    for label, points in run.curve.items():
        if points:
            axes.plot(
                *zip(*points, strict=True), marker="." if len(points) < 50 else None, label=label
            )
    axes.set_xlabel(run.curve_axes[0])
    axes.set_ylabel(run.curve_axes[1])
    if len(run.curve) > 1:
        axes.legend()
    axes.set_title(f"{name}: {run.budget}")
    figure.savefig(path, dpi=110)
    return path


def hours(seconds: float | None) -> str:
    """A wall time in words.

    Example:
        >>> hours(5400), hours(None)
        ('1.5 h', 'not recorded')
    """
    return "not recorded" if seconds is None else f"{seconds / 3600:.1f} h"


def _kept(facts: Mapping[str, Any]) -> str:
    """The card's sentence on which policy of the run it ships ("" for the last one)."""
    kept_steps = facts.get("kept_steps")
    if kept_steps is None:
        return ""
    return (
        f" It is the policy of {kept_steps:,} env steps, the best of the run's periodic "
        "evaluations on its selection seeds (the training curve)."
    )


def card_text(facts: Mapping[str, Any], settings_yaml: str) -> str:
    """The card (Markdown) of :func:`ship_policy`'s ``facts``."""
    name = facts["name"]
    what = "PPO from scratch" if facts["kind"] == "ppo" else "behaviour cloning with DAgger"
    crop = facts.get("front_crop")
    inputs = (
        f"the three camera streams and a narrow forward camera cut from the front one on the "
        f"client (its centre {crop}: `env.front_crop={crop}`, which every env that drives it "
        "gets)"
        if crop is not None
        else "the three camera streams only"
    )
    env_flags = "--env.type=oasis --env.task=urban" + (
        f" --env.front_crop={crop}" if crop is not None else ""
    )
    rows = [
        f"| {'report' if i == 0 else 'held out'}: {row['scene']} | "
        f"{', '.join(str(s) for s in row['seeds'])} | {row['episodes']} | "
        f"{row['distance']:.1f} ± {row['stderr']:.1f} | {row['baseline_distance']:.1f} | "
        f"{row['ratio']:.2f}x | {row['collision_rate']:.2f} | "
        f"{row['baseline_collision_rate']:.2f} |"
        for i, row in enumerate(facts["figures"])
    ]
    return "\n".join(
        [
            f"# pretrained:{name}",
            "",
            f"A camera policy trained by {what} ({facts['budget']}) on "
            f"{len(facts['training_prompts'])} prompts: "
            f"{'; '.join(facts['training_prompts'])}.{_kept(facts)} It reads {inputs}, so it "
            "drives any endpoint, the hosted service included.",
            "",
            "Load it:",
            "",
            "```bash",
            f"oasis-torchrl eval policy=pretrained:{name}",
            f"oasis-torchrl serve-policy pretrained:{name}",
            f"lerobot-eval --policy.path=$(oasis-torchrl pretrained path {name}) \\",
            f"    {env_flags} --eval.batch_size=8 --eval.n_episodes=16",
            "```",
            "",
            "## Training",
            "",
            "| | |",
            "|---|---|",
            f"| command | `{facts['command']}` |",
            f"| commit | {facts['commit'] or 'unknown'} |",
            f"| wall time | {hours(facts['wall_seconds'])} |",
            f"| machine | {facts['machine']} |",
            "",
            "## Figures",
            "",
            f"Mean distance before collision (m, ± standard error over episodes) and collision "
            f"rate, beside the best constant action (`{facts['baseline']}`) on the same "
            "episodes. Distances need the embedded server's ground truth: the card was written "
            "on it.",
            "",
            f"| scene | seeds | episodes | {name} (m) | best constant (m) | ratio | "
            f"collisions | constant's collisions |",
            "|---|---|---|---|---|---|---|---|",
            *rows,
            "",
            "## Training curve",
            "",
            f"![training curve]({CURVE})",
            "",
            "## Settings",
            "",
            "```yaml",
            settings_yaml.rstrip(),
            "```",
            "",
        ]
    )


def load_card(folder: Path) -> dict[str, Any] | None:
    """A shipped policy's card facts (``card.json``; None if it has none).

    Example:
        >>> load_card(Path("nowhere")) is None
        True
    """
    path = Path(folder) / CARD_DATA
    return json.loads(path.read_text()) if path.is_file() else None
