"""The narrow forward crop's pre-registered rule, run as written
(docs/experiments/2026-11-28-narrow-crop.md): adopt ``env.front_crop`` or not.

Both arms are the learning benchmark's 64-demonstration clone without DAgger, trained with the
same seed on the same demonstrations (recorded once, with the crop); the crop arm reads four
cameras, the other three. Both are evaluated on the same world frames (the env renders for the
crop in both arms; only the policy's input differs): the report seed (the benchmark's
``PROTOCOL``: seed 1000, 32 episodes) and the benchmark's held-out prompts and seed (8 episodes
each), paired episode by episode. The crop is adopted when its paired gain on the report seed is
more than 2 standard errors and its held-out mean is not lower by more than 2 standard errors.

Every stage is kept under ``--output-dir`` and reused by a rerun. Prints JSON (both arms' figures,
the paired differences, the decision) and writes it to ``--results``.

Usage: ``python benchmarks/front_crop_rule.py [--output-dir outputs/front_crop]`` (hours on
2 CPU cores).
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

from learning import CLONE_PRESET, PROTOCOL, StageCache, held_out_config
from omegaconf import DictConfig, OmegaConf

from oasis_torchrl.allocator import keep_batches_in_heap
from oasis_torchrl.config import load_config
from oasis_torchrl.evaluation import paired_difference
from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.train.bc import train_bc
from oasis_torchrl.train.plan import plan_run
from oasis_torchrl.train.stages import gather_demonstrations

CROP = 0.25
"""The crop's fraction of the front frame (the rule's)."""
RULE = {
    "record.episodes": 64,
    "bc.train.steps": 2000,
    "dagger.rounds": 0,
    "env.front_crop": CROP,
}
"""The rule's settings over the learning benchmark's clone (:data:`learning.PROTOCOL`)."""
HELD_OUT_EPISODES = 8
MARGIN = 2.0
"""Standard errors of the paired difference the rule asks for."""


def rule_config(output_dir: Path, overrides: list[str]) -> DictConfig:
    """The benchmark's clone config with the rule's settings, writing under ``output_dir``
    (``overrides``, ``KEY=VALUE``, only shrink it for a smoke run: the rule is the defaults)."""
    values = [*PROTOCOL.items(), *RULE.items(), ("output_dir", str(output_dir))]
    return load_config("demo", overrides, file=CLONE_PRESET, values=values)


def train_arm(cfg: DictConfig, clone: DictConfig, crop: bool) -> Path:
    """Train one arm's clone from the run's first clone settings ``clone`` (reused when its
    policy exists); the path of its policy."""
    folder = Path(cfg.output_dir) / ("bc_crop" if crop else "bc_no_crop")
    policy = folder / "policy"
    if policy.exists():
        return policy
    arm: dict[str, Any] = {"output_dir": str(folder)}
    if not crop:
        arm["dataset"] = {"cameras": list(CAMERAS)}
        arm["policy"] = {"front_crop": None}
    train_bc(OmegaConf.merge(clone, arm))
    return policy


def decide(report: dict[str, Any], held_out: dict[str, Any]) -> dict[str, Any]:
    """The rule's decision from both arms' evaluations on the report seed and held out.

    >>> gain = {"mean": 10.0, "stderr": 4.0}
    >>> decide({"difference": gain}, {"difference": {"mean": -3.0, "stderr": 2.0}})["adopt"]
    True
    """
    gain, held = report["difference"], held_out["difference"]
    gains = gain["mean"] > MARGIN * gain["stderr"]
    keeps = held["mean"] >= -MARGIN * held["stderr"]
    return {"gains_on_report_seed": gains, "holds_on_held_out": keeps, "adopt": gains and keeps}


def compare(cache: StageCache, cfg: DictConfig, arms: dict[str, str]) -> dict[str, Any]:
    """Both arms' evaluations under ``cfg`` and their paired difference (crop minus none)."""
    reports = cache.evaluate(cfg, arms)
    summary = {
        name: {k: v for k, v in r.items() if k != "per_episode"} for name, r in reports.items()
    }
    return {**summary, "difference": paired_difference(reports["crop"], reports["no_crop"])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", type=Path, default=Path("outputs/front_crop"))
    parser.add_argument("--results", type=Path, default=Path("benchmarks/results"))
    parser.add_argument("overrides", nargs="*", metavar="KEY=VALUE", help="smoke runs only")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s", force=True)
    keep_batches_in_heap()  # as the oasis-torchrl command does

    cfg = rule_config(args.output_dir, args.overrides)
    plan = plan_run(cfg)
    gather_demonstrations(plan.record)
    clone = plan.clone[0].config
    arms = {"crop": str(train_arm(cfg, clone, True)), "no_crop": str(train_arm(cfg, clone, False))}
    cache = StageCache(args.output_dir / "evaluations.json")
    report = compare(cache, cfg, arms)
    episodes = min(HELD_OUT_EPISODES, cfg.eval.episodes)
    held_out = compare(cache, held_out_config(cfg, episodes), arms)
    result = {
        "settings": {**RULE, "overrides": args.overrides},
        "report_seed": report,
        "held_out": held_out,
        **decide(report, held_out),
    }
    text = json.dumps(result, indent=2)
    print(text)
    args.results.mkdir(parents=True, exist_ok=True)
    (args.results / "front_crop_rule.json").write_text(text + "\n")


if __name__ == "__main__":
    main()
