"""The frames-only reward checked against the embedded world's ground truth, before any RL run.

Every policy drives the held-out scenes (prompts and seeds no training run uses) on the embedded
server with ground truth; collisions do not end the episodes, so what the frames show after a
crash is scored too. On every step both frames-only rewards read the frames the hosted service
would send: the motion reward (:class:`~oasis_torchrl.rewards.MotionReward`, the frames-only
default) and the reference's depth-collision reward with the small depth network, side by side.
Ground truth judges them:

- progress per chunk: seen vs true (Pearson), and each condition's distance (ratio of sums);
- crashes seen within 2 chunks of the true collision, and false ends in autopilot episodes;
- the collision-ahead score: collisions flagged 1-5 chunks before impact at the threshold that
  keeps false alarms at 5% of the autopilot's episodes, and the chunk-level ROC AUC;
- the policies ranked by return as ground truth ranks them by distance before a collision
  (Kendall tau), and the per-episode return against that distance (Pearson);
- each policy's distance seen over true (before its collisions) and how much its steering
  changes from one action to the next within a chunk: a learned policy that games the reward
  (``--policies`` takes its folder beside the references) is seen farther than it drives;
- CPU per row per chunk of the motion reward at 96x64 and at the hosted 768x512.

Prints JSON and writes it (and a plot) with ``--output``::

    python benchmarks/frames_reward.py --output benchmarks/results/frames_reward
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from _ranking import kendall_tau
from tensordict import TensorDict, TensorDictBase

from oasis_torchrl.config import EnvConfig
from oasis_torchrl.config.env import EmbeddedServerConfig, RewardConfig
from oasis_torchrl.config.scenes import HELD_OUT_SCENES, REWARD_CHECK_SEEDS
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.envs.driving import drive
from oasis_torchrl.envs.factory import make_env, make_frames_reward
from oasis_torchrl.protocol import ACTION_DIM, ACTION_NAMES, FRONT, HOSTED_FRAME_SIZE
from oasis_torchrl.rewards import NoReward
from oasis_torchrl.train.motion_checks import pearson, roc_auc

POLICIES = (
    "autopilot",
    "pretrained:clone",
    "pretrained:ppo-scratch",
    "constant:throttle=1.0,steering=0.0",
    "constant:throttle=0.5,steering=0.0",
    "constant:throttle=0.25,steering=0.0",
    "scripted:throttle=sine:1.0:37,steering=sine:1.0:23",
    "scripted:throttle=1.0,steering=weave:0.088:20:100",
)
"""The reference policies the rewards must rank as ground truth does (the sine driver stands in
for a random policy: full swings of both pedals at unrelated periods)."""
REWARDS = ("motion", "depth")
AHEAD_CHUNKS = 5
CRASH_WINDOW = 2


@dataclass
class Episodes:
    """Per-row, per-step values of one policy's episodes ``[E, T]`` (numpy)."""

    true_progress: list[np.ndarray] = field(default_factory=list)
    collided: list[np.ndarray] = field(default_factory=list)
    steering_change: list[np.ndarray] = field(default_factory=list)
    reward: dict[str, list[np.ndarray]] = field(default_factory=dict)
    ended: dict[str, list[np.ndarray]] = field(default_factory=dict)
    progress: dict[str, list[np.ndarray]] = field(default_factory=dict)
    ahead: dict[str, list[np.ndarray]] = field(default_factory=dict)
    prompts: list[str] = field(default_factory=list)

    def add(self, name: str, key: str, value: torch.Tensor) -> None:
        """Append one step's ``[E]`` value of reward ``name``."""
        getattr(self, key).setdefault(name, []).append(value.reshape(-1).float().cpu().numpy())

    def stacked(self) -> dict[str, object]:
        """Every value as ``[E, T]`` arrays."""

        def stack(values: list[np.ndarray]) -> np.ndarray:
            return np.stack(values, axis=1)

        return {
            "true_progress": stack(self.true_progress),
            "collided": stack(self.collided),
            "steering_change": stack(self.steering_change),
            **{
                key: {name: stack(v) for name, v in getattr(self, key).items()}
                for key in ("reward", "ended", "progress", "ahead")
            },
        }


def scorer(rewards: dict[str, object], episodes: Episodes) -> Callable[[TensorDictBase], None]:
    """The per-step hook: ground truth and both rewards' outputs of the step."""

    previous: dict[str, torch.Tensor] = {}

    def on_step(td: TensorDictBase) -> None:
        step = td.get("next")
        truth = step.get("truth")
        last = truth.get("progress")[:, -1]
        episodes.true_progress.append((last - previous.get("progress", 0.0)).numpy())
        previous["progress"] = last
        episodes.collided.append(truth.get("collided").gt(0.5).any(-1).numpy())
        actions = td.get("action").reshape(len(last), -1, ACTION_DIM)
        steering = actions[..., ACTION_NAMES.index("steering")]
        episodes.steering_change.append(steering.diff(dim=-1).abs().mean(-1).numpy())
        scored_input = step.clone(False).set("action", td.get("action"))
        for name, reward in rewards.items():
            out = reward(scored_input)
            terms = out.get("reward_terms")
            episodes.add(name, "reward", out.get("reward"))
            episodes.add(name, "ended", out.get("terminated"))
            episodes.add(name, "progress", terms.get(reward.terms[0]))
            risk = "collision_ahead" if name == "motion" else "collision_risk"
            episodes.add(name, "ahead", terms.get(risk))

    return on_step


def drive_policy(
    spec: str,
    prompts: tuple[str, ...],
    episodes: int,
    steps: int,
    size: tuple[int, int],
    reward_cfg: RewardConfig,
) -> dict[str, object]:
    """One policy's episodes on every prompt and seed, scored by both rewards."""
    driver = load_driver(spec)
    rows = [prompt for prompt in prompts for _ in range(episodes)]
    cfg = EnvConfig(server=EmbeddedServerConfig(height=size[0], width=size[1]))
    env = make_env(
        cfg,
        num_envs=len(rows),
        prompts=rows,
        max_steps=steps,
        image_size=driver.image_size,
        all_frames=True,
        frame_stack=driver.frame_stack,
        expert=driver.needs_expert,
        front_crop=driver.front_crop,
        reward=NoReward(),
        terminate_on_collision=False,
    )
    parts = []
    try:
        for seed in REWARD_CHECK_SEEDS:
            rewards = {name: make_frames_reward(reward_cfg, name) for name in REWARDS}
            collected = Episodes(prompts=rows)
            env.set_seed(seed)
            on_step = scorer(rewards, collected)

            drive(
                env,
                driver,
                on_step,
                until=lambda: False,
                max_steps=steps,
                reset_finished=False,
                on_reset=lambda td, rewards=rewards: [r.reset(None) for r in rewards.values()],
            )
            parts.append(collected.stacked())
    finally:
        env.close()
    return _concat(parts) | {"prompts": rows * len(REWARD_CHECK_SEEDS)}


def _concat(parts: list[dict[str, object]]) -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in parts[0].items():
        if isinstance(value, dict):
            out[key] = {name: np.concatenate([p[key][name] for p in parts]) for name in value}
        else:
            out[key] = np.concatenate([p[key] for p in parts])
    return out


def first_index(mask: np.ndarray) -> np.ndarray:
    """Per row of ``[E, T]``, the first True step, or T where none."""
    return np.where(mask.any(1), mask.argmax(1), mask.shape[1])


def judged(run: dict[str, object], reward: str) -> dict[str, np.ndarray]:
    """Per episode: true distance before the collision, the reward's return up to its own end,
    the collision step and the reward's first end."""
    true_progress, collided = run["true_progress"], run["collided"]
    steps = true_progress.shape[1]
    hit = first_index(collided)
    within_truth = np.arange(steps)[None, :] <= np.minimum(hit, steps - 1)[:, None]
    ended = first_index(run["ended"][reward] > 0.5)
    within_own = np.arange(steps)[None, :] <= np.minimum(ended, steps - 1)[:, None]
    return {
        "distance": (true_progress * within_truth).sum(1),
        "return": (run["reward"][reward] * within_own).sum(1),
        "seen": (run["progress"][reward] * within_truth).sum(1),
        "hit": hit,
        "ended": ended,
    }


def checks(runs: dict[str, dict[str, object]], reward: str) -> dict[str, object]:
    """The report's rows for one reward over every policy's episodes."""
    chunk_true = np.concatenate([r["true_progress"][r["collided"] == 0] for r in runs.values()])
    chunk_seen = np.concatenate([r["progress"][reward][r["collided"] == 0] for r in runs.values()])
    per_policy = {spec: judged(run, reward) for spec, run in runs.items()}
    crashed = caught = 0
    for values in per_policy.values():
        crashes = values["hit"] < runs_steps(runs)
        crashed += int(crashes.sum())
        caught += int(((values["ended"] - values["hit"] <= CRASH_WINDOW) & crashes).sum())
    autopilot = per_policy["autopilot"]
    steps = runs_steps(runs)
    clean = autopilot["hit"] >= steps
    false_ends = float(((autopilot["ended"] < steps) & clean).sum() / max(clean.sum(), 1))
    return {
        "progress_pearson": pearson(chunk_seen, chunk_true),
        "distance_ratio": distance_ratios(runs, per_policy),
        "crashes_seen_within_2": caught / max(crashed, 1),
        "crashes": crashed,
        "false_ends_autopilot": false_ends,
        "ahead": ahead_checks(runs, reward),
        "ranking": ranking(per_policy),
        "seen_over_true": {
            spec: float(values["seen"].sum() / max(values["distance"].sum(), 1e-6))
            for spec, values in per_policy.items()
        },
        "return_vs_distance_pearson": pearson(
            np.concatenate([v["return"] for v in per_policy.values()]),
            np.concatenate([v["distance"] for v in per_policy.values()]),
        ),
    }


def runs_steps(runs: dict[str, dict[str, object]]) -> int:
    """Steps of every episode (all runs drive the same count)."""
    return next(iter(runs.values()))["true_progress"].shape[1]


def distance_ratios(
    runs: dict[str, dict[str, object]], per_policy: dict[str, dict[str, np.ndarray]]
) -> dict[str, float]:
    """Seen over true distance before the collision, summed per held-out prompt."""
    seen: dict[str, float] = {}
    true: dict[str, float] = {}
    for spec, values in per_policy.items():
        for prompt, s, t in zip(
            runs[spec]["prompts"], values["seen"], values["distance"], strict=True
        ):
            seen[prompt] = seen.get(prompt, 0.0) + float(s)
            true[prompt] = true.get(prompt, 0.0) + float(t)
    return {prompt: seen[prompt] / true[prompt] for prompt in seen if true[prompt] > 0}


def ahead_checks(runs: dict[str, dict[str, object]], reward: str) -> dict[str, float]:
    """The collision-ahead score: chunk-level AUC, and collisions flagged 1-5 chunks ahead at
    the threshold that keeps the autopilot's episodes 95% free of alarms."""
    scores, labels, flagged_max, alarm_max = [], [], [], []
    for spec, run in runs.items():
        score = run["ahead"][reward]
        hit = first_index(run["collided"] > 0)
        steps = score.shape[1]
        t = np.arange(steps)[None, :]
        before = t < hit[:, None]
        soon = before & (hit[:, None] - t <= AHEAD_CHUNKS)
        scores.append(score[before])
        labels.append(soon[before])
        window = before & soon
        for row in np.flatnonzero(hit < steps):
            if window[row].any():
                flagged_max.append(score[row][window[row]].max())
        if spec == "autopilot":
            alarm_max += [score[row][before[row]].max() for row in np.flatnonzero(hit >= steps)]
    threshold = float(np.quantile(alarm_max, 0.95)) if alarm_max else math.nan
    flagged = np.array(flagged_max)
    return {
        "auc": roc_auc(np.concatenate(scores), np.concatenate(labels)),
        "threshold_at_5pct_alarms": threshold,
        "flagged_1_to_5_ahead": float((flagged > threshold).mean()) if flagged.size else math.nan,
    }


def ranking(per_policy: dict[str, dict[str, np.ndarray]]) -> dict[str, object]:
    """Mean return and mean true distance of each policy, and Kendall's tau between them."""
    returns = {spec: float(v["return"].mean()) for spec, v in per_policy.items()}
    distances = {spec: float(v["distance"].mean()) for spec, v in per_policy.items()}
    specs = list(per_policy)
    tau = kendall_tau([returns[s] for s in specs], [distances[s] for s in specs])
    return {"kendall_tau": tau, "mean_return": returns, "mean_distance": distances}


def cpu_cost(
    size: tuple[int, int], reward_cfg: RewardConfig, rows: int = 8, repeats: int = 20
) -> dict[str, float]:
    """Wall and CPU milliseconds per row per chunk of the motion reward on frames of ``size``
    (a batch of ``rows``, as the env scores it)."""
    reward = make_frames_reward(reward_cfg, "motion")
    frames = torch.randint(0, 255, (rows, 4, *size, 3), dtype=torch.uint8)
    td = make_td(frames)
    reward(td)
    started, cpu = time.perf_counter(), time.process_time()
    for _ in range(repeats):
        reward.reset(None)
        reward(td)
    scale = 1000.0 / repeats / rows
    return {
        "wall_ms": (time.perf_counter() - started) * scale,
        "cpu_ms": (time.process_time() - cpu) * scale,
    }


def make_td(frames: torch.Tensor) -> TensorDictBase:
    """A step's reward input: the front frames and an action chunk."""
    rows = frames.shape[0]
    return TensorDict({("pixels", FRONT): frames, "action": torch.zeros(rows, 4, 2)}, [rows])


def plot(report: dict[str, object], path: Path) -> None:
    """Mean return against mean true distance, one point per policy, per reward."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(REWARDS), figsize=(11, 4.2))
    for axis, name in zip(axes, REWARDS, strict=True):
        rank = report["checks"][name]["ranking"]
        for spec, distance in rank["mean_distance"].items():
            axis.scatter(distance, rank["mean_return"][spec])
            axis.annotate(spec.split(",")[0], (distance, rank["mean_return"][spec]), fontsize=7)
        axis.set_title(f"{name}: Kendall tau {rank['kendall_tau']:.2f}")
        axis.set_xlabel("true distance before a collision (m)")
        axis.set_ylabel("return under the reward")
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def parse_arguments(argv: list[str] | None = None) -> argparse.Namespace:
    """The flags of ``argv`` (default: the process's)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=2, help="episodes per prompt and seed")
    parser.add_argument("--steps", type=int, default=100, help="chunks per episode")
    parser.add_argument(
        "--hosted-episodes",
        type=int,
        default=1,
        help="episodes per prompt and seed rendered at the hosted 768x512",
    )
    parser.add_argument("--policies", nargs="+", default=list(POLICIES))
    parser.add_argument(
        "--motion-model",
        default="small",
        help="the motion network checked: small (the shipped one) or a weights file",
    )
    parser.add_argument("--output", type=Path, help="write <output>.json and <output>.png")
    return parser.parse_args(argv)


def main() -> None:
    """Drive every policy, check both rewards, print (and write) the report."""
    args = parse_arguments()
    # One torch thread: on a shared 2-core machine two OpenMP threads wait on each other (a
    # chunk's reward took 26 times as long in this script beside other jobs).
    torch.set_num_threads(1)
    started = time.monotonic()
    reward_cfg = RewardConfig(motion_model=args.motion_model)
    report: dict[str, object] = {
        "prompts": list(HELD_OUT_SCENES),
        "seeds": list(REWARD_CHECK_SEEDS),
        "motion_model": args.motion_model,
    }
    runs = {
        spec: drive_policy(spec, HELD_OUT_SCENES, args.episodes, args.steps, (64, 96), reward_cfg)
        for spec in args.policies
    }
    report["checks"] = {name: checks(runs, name) for name in REWARDS}
    report["steering_change_per_action"] = {
        spec: float(run["steering_change"].mean()) for spec, run in runs.items()
    }
    if args.hosted_episodes:
        hosted = {
            spec: drive_policy(
                spec,
                HELD_OUT_SCENES,
                args.hosted_episodes,
                args.steps,
                HOSTED_FRAME_SIZE,
                reward_cfg,
            )
            for spec in ("autopilot", "constant:throttle=1.0,steering=0.0")
        }
        report["hosted_size"] = {
            name: {key: value for key, value in checks(hosted, name).items() if key != "ranking"}
            for name in REWARDS
        }
    report["cost_per_row_chunk"] = {
        "96x64": cpu_cost((64, 96), reward_cfg),
        "768x512": cpu_cost(HOSTED_FRAME_SIZE, reward_cfg),
    }
    report["seconds"] = round(time.monotonic() - started, 1)
    text = json.dumps(report, indent=2, default=float)
    print(text)
    if args.output:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.with_suffix(".json").write_text(text)
        plot(report, args.output.with_suffix(".png"))


if __name__ == "__main__":
    main()
