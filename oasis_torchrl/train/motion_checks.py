"""The frames-only reward's checks on labelled episodes: does it see the progress and the crashes
the labels say, and end nothing else?

Labels come from the embedded world's ground truth or from a person's crash marks on the drive
page (:mod:`oasis_torchrl.train.motion_dataset`); progress is only checked where it is known.
The reward runs as the env runs it (:class:`~oasis_torchrl.rewards.motion.MotionReward`, chunk
by chunk, its stuck rule included), so the figures are the reward's, not the network's alone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from tensordict import TensorDict

from oasis_torchrl.models.motion import MotionNet
from oasis_torchrl.protocol import FRONT
from oasis_torchrl.rewards.motion import MotionReward, MotionRewardConfig
from oasis_torchrl.train.motion_chunks import MotionChunks

SEEN_WITHIN = 2
"""Chunks either side of a labelled crash within which the reward's end counts as seeing it."""


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two flat arrays (NaN when one is constant or too short).

    Example:
        >>> pearson(np.array([1.0, 2.0, 3.0]), np.array([2.0, 4.0, 7.0])) > 0.99
        True
    """
    if a.size < 2 or a.std() == 0 or b.std() == 0:
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])


def roc_auc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve of ``scores`` for bool ``labels`` (ties count half; NaN without
    both classes).

    Example:
        >>> roc_auc(np.array([0.9, 0.2, 0.4]), np.array([True, False, False]))
        1.0
    """
    positive, negative = scores[labels], scores[~labels]
    if positive.size == 0 or negative.size == 0:
        return math.nan
    greater = (positive[:, None] > negative[None, :]).mean()
    ties = (positive[:, None] == negative[None, :]).mean()
    return float(greater + 0.5 * ties)


def _drive_reward(reward: MotionReward, episode: MotionChunks) -> dict[str, np.ndarray]:
    """The reward's paid progress, collision-ahead and end flag per chunk of one episode."""
    reward.reset()
    paid, ahead, ended = [], [], []
    for t in range(len(episode)):
        step = TensorDict(
            {("pixels", FRONT): episode.frames[t : t + 1], "action": episode.actions[t : t + 1]},
            [1],
        )
        out = reward(step)
        paid.append(float(out["reward_terms", "seen_progress"]))
        ahead.append(float(out["reward_terms", "collision_ahead"]))
        ended.append(bool(out["terminated"]))
    return {"paid": np.array(paid), "ahead": np.array(ahead), "ended": np.array(ended, bool)}


def check_reward(
    net: MotionNet,
    episodes: Sequence[MotionChunks],
    config: MotionRewardConfig | None = None,
) -> dict[str, float]:
    """The reward's figures on labelled ``episodes`` (each one episode's chunks, in order).

    Returns: ``episodes`` and ``crashed`` (labelled); ``crashes_seen`` (share of crashed
    episodes the reward ends within :data:`SEEN_WITHIN` chunks of the labelled crash);
    ``early_ends`` (share of crashed episodes it ends before that); ``false_ends`` (share of the
    others it ends at all); ``ahead_auc`` (collision-ahead, the 1-5 chunks before a crash
    against every chunk of the episodes without one); ``progress_pearson`` (paid against
    labelled progress per chunk, NaN where progress is not labelled).

    Example:
        >>> from oasis_torchrl.models.motion import MotionNetConfig
        >>> net = MotionNet(MotionNetConfig(image_size=(64, 96)))
        >>> still = MotionChunks(torch.zeros(3, 4, 64, 96, 3, dtype=torch.uint8),
        ...     torch.zeros(3, 4, 2), torch.zeros(3), torch.zeros(3, dtype=torch.bool),
        ...     torch.zeros(3, dtype=torch.long), torch.zeros(3, dtype=torch.long))
        >>> figures = check_reward(net, [still])
        >>> figures["episodes"], figures["crashed"], math.isnan(figures["crashes_seen"])
        (1, 0, True)
    """
    reward = MotionReward(net.eval(), config)
    counts = {"seen": 0, "early": 0, "false": 0, "crashed": 0}
    scores, labels, paid, known = [], [], [], []
    horizon = net.cfg.horizon
    with torch.inference_mode():
        for episode in episodes:
            run = _drive_reward(reward, episode)
            crashes = episode.collided.nonzero().flatten()
            end = int(run["ended"].argmax()) if run["ended"].any() else None
            chunks = np.arange(len(episode))
            if crashes.numel():
                crash = int(crashes[0])
                counts["crashed"] += 1
                counts["seen"] += end is not None and abs(end - crash) <= SEEN_WITHIN
                counts["early"] += end is not None and end < crash - SEEN_WITHIN
                before = (crash - chunks >= 1) & (crash - chunks <= horizon)
                scores.append(run["ahead"][before])
                labels.append(np.ones(int(before.sum()), bool))
            else:
                counts["false"] += end is not None
                scores.append(run["ahead"])
                labels.append(np.zeros(len(episode), bool))
            paid.append(run["paid"])
            known.append(episode.progress.numpy())
    crashed, others = counts["crashed"], len(episodes) - counts["crashed"]
    progress, estimate = np.concatenate(known), np.concatenate(paid)
    labelled = np.isfinite(progress)
    return {
        "episodes": len(episodes),
        "crashed": crashed,
        "crashes_seen": counts["seen"] / crashed if crashed else math.nan,
        "early_ends": counts["early"] / crashed if crashed else math.nan,
        "false_ends": counts["false"] / others if others else math.nan,
        "ahead_auc": roc_auc(np.concatenate(scores), np.concatenate(labels)),
        "progress_pearson": pearson(estimate[labelled], progress[labelled]),
    }
