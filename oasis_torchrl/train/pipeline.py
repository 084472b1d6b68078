"""The main job in one call: record -> behaviour cloning -> PPO fine-tuning -> evaluation.

1. ``record``: autopilot demonstrations as a LeRobot dataset (one row per frame), with noise
   injected into the executed actions (:mod:`oasis_torchrl.train.demonstrations`);
2. ``bc``: behaviour cloning on it (``configs/bc.yaml`` plus the config's ``bc`` overrides);
3. ``ppo``: PPO fine-tuning warm-started from the cloned policy (``configs/ppo.yaml`` plus the
   ``ppo`` overrides, the shared ``env`` and ``eval`` sections);
4. ``eval``: the reference drivers, the cloned and the fine-tuned policy on the same fixed
   prompts and seeds; the final policy's episodes go to rerun / a LeRobot dataset if configured.

Every stage shows a progress bar. A stage whose output already exists is reused (delete the
folder to redo it), so re-running after an interruption continues where it stopped. Outputs under
``output_dir``: ``demos/`` (dataset), ``bc/policy/``, ``ppo/policy/`` (LeRobot policy folders),
``ppo/checkpoints/latest.pt``, ``summary.json``. Config: ``configs/demo.yaml``.
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

from oasis_torchrl.train.config import load_config, save_config
from oasis_torchrl.train.demonstrations import ActionNoise, record_demonstrations
from oasis_torchrl.train.evaluate import Evaluator
from oasis_torchrl.train.policy_source import load_policy

logger = logging.getLogger(__name__)

REFERENCE_KEY = "reference"


@dataclass
class PipelineResult:
    """Where the pipeline's outputs are, and the evaluation of every policy."""

    dataset: Path
    bc_policy: Path
    ppo_policy: Path
    summary_path: Path
    evaluations: dict[str, dict[str, float]] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)


@contextmanager
def _timed(seconds: dict[str, float], stage: str) -> Iterator[None]:
    logger.info("pipeline stage %s", stage)
    started = time.perf_counter()
    yield
    seconds[stage] = round(time.perf_counter() - started, 1)


def demonstrations(cfg: DictConfig, root: Path) -> Path:
    """Record ``cfg.record.episodes`` noisy-execution autopilot episodes into ``root`` (a
    complete earlier recording is reused)."""
    from oasis_torchrl.commands._dataset_args import quiet_dataset_libraries

    info = root / "meta" / "info.json"
    if info.exists():
        episodes = json.loads(info.read_text())["total_episodes"]
        if episodes >= cfg.record.episodes:
            logger.info("reusing %s (%d episodes)", root, episodes)
            return root
        raise FileExistsError(
            f"{root} holds {episodes} of {cfg.record.episodes} episodes; delete it"
        )
    quiet_dataset_libraries()
    return record_demonstrations(
        cfg.env,
        root,
        episodes=cfg.record.episodes,
        seed=cfg.record.seed,
        noise=ActionNoise(**cfg.record.noise),
        progress=cfg.progress,
    )


def stage_configs(cfg: DictConfig, dataset: Path) -> tuple[DictConfig, DictConfig]:
    """The BC and PPO configs of a pipeline config (base configs, shared sections, overrides).

    Example:
        >>> bc, ppo = stage_configs(load_config("demo", ["output_dir=/tmp/d"]), Path("/tmp/d/x"))
        >>> ppo.init_from, bc.dataset.root
        ('/tmp/d/bc/policy', '/tmp/d/x')
    """
    out = Path(cfg.output_dir)
    shared = {"seed": cfg.seed, "progress": cfg.progress}
    evaluation = {key: value for key, value in cfg.eval.items() if key != REFERENCE_KEY}
    bc = OmegaConf.merge(
        load_config("bc"),
        shared,
        {"output_dir": str(out / "bc"), "dataset": {"root": str(dataset)}, "eval": {"episodes": 0}},
        cfg.bc,
    )
    bc.policy.image_size = list(cfg.env.image_size)
    ppo = OmegaConf.merge(
        load_config("ppo"),
        shared,
        {
            "output_dir": str(out / "ppo"),
            "init_from": str(out / "bc" / "policy"),
            "env": cfg.env,
            "eval": evaluation,
        },
        cfg.ppo,
    )
    return bc, ppo


def evaluate_all(cfg: DictConfig, policies: dict[str, str]) -> dict[str, dict[str, float]]:
    """Evaluate each named policy spec on the config's fixed prompts and seeds.

    The last policy's episodes are also recorded (``eval.rerun`` / ``eval.lerobot``).
    """
    plain = OmegaConf.merge(cfg.eval, {"rerun": None, "lerobot": None})
    results = {}
    names = list(policies)
    for name in names:
        source = load_policy(policies[name])
        eval_cfg = cfg.eval if name == names[-1] else plain
        with Evaluator(
            cfg.env, eval_cfg, image_size=source.image_size, progress=cfg.progress
        ) as evaluator:
            results[name] = evaluator.evaluate(source.policy).summary()
        logger.info("%s: %s", name, results[name])
    return results


def run_pipeline(cfg: DictConfig) -> PipelineResult:
    """Run record -> BC -> PPO fine-tuning -> evaluation as ``cfg`` (``configs/demo.yaml``) says.

    Example:
        >>> result = run_pipeline(load_config("demo"))  # doctest: +SKIP
        >>> result.evaluations["bc+ppo"]["mean_distance"]  # doctest: +SKIP
    """
    from oasis_torchrl.train.bc import train_bc
    from oasis_torchrl.train.ppo import train_ppo

    out = Path(cfg.output_dir)
    save_config(cfg, out / "config.yaml")
    seconds: dict[str, float] = {}
    with _timed(seconds, "record"):
        dataset = demonstrations(cfg, out / "demos")
    bc_cfg, ppo_cfg = stage_configs(cfg, dataset)
    bc_policy = Path(bc_cfg.output_dir) / "policy"
    with _timed(seconds, "bc"):
        if (bc_policy / "model.safetensors").exists():
            logger.info("reusing %s", bc_policy)
        else:
            train_bc(bc_cfg)
    ppo_policy = Path(ppo_cfg.output_dir) / "policy"
    with _timed(seconds, "ppo"):
        if (ppo_policy / "model.safetensors").exists():
            logger.info("reusing %s", ppo_policy)
        else:
            if (Path(ppo_cfg.output_dir) / "checkpoints" / "latest.pt").exists():
                ppo_cfg.resume = "latest"
            train_ppo(ppo_cfg)
    references = {str(spec): str(spec) for spec in cfg.eval.get(REFERENCE_KEY, [])}
    policies: dict[str, Any] = {**references, "bc": str(bc_policy), "bc+ppo": str(ppo_policy)}
    with _timed(seconds, "eval"):
        evaluations = evaluate_all(cfg, policies)
    summary = out / "summary.json"
    summary.write_text(json.dumps({"evaluations": evaluations, "seconds": seconds}, indent=2))
    logger.info("pipeline done in %.0f s; summary in %s", sum(seconds.values()), summary)
    return PipelineResult(dataset, bc_policy, ppo_policy, summary, evaluations, seconds)
