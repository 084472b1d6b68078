"""Evaluation: fixed prompts and seeds in; mean distance before collision, collision rate and
return out; and the one rule that selects between policies.

Each env row drives exactly one episode (no resets) until it ends (collision, or ``max_steps``)
or every row has ended. The distance is the embedded server's odometer at the episode's last
step (``("truth", "distance")``; NaN on servers without ground truth); a collision is the
episode ending *terminated* (the ground-truth collision, or the reward's termination); the
return sums the rewards up to and including that step. With the same policy, prompts, seeds
and server, the numbers are the same run after run.

Every endpoint also gets what frames give: the return under the frames-only reward, the episode
length, the likely-collision terminations and its progress term
(:class:`~oasis_torchrl.evaluation.rollouts.ReferenceScore`). On an endpoint that sends frames
only (the hosted service, a hosted-like server) there is no distance and no ground-truth
collision, and the report says ``ground_truth: false``. Such an endpoint ignores seeds, so its
episodes cannot be paired across policies: comparisons (:func:`difference`) then use the
unpaired (Welch) standard error of the difference in mean return.

The modules, one concern each: :mod:`~oasis_torchrl.evaluation.reports` (episode results,
reports, reading them back), :mod:`~oasis_torchrl.evaluation.selection` (differences between
reports, and which policy to keep: PPO, behaviour cloning, the main job and ``oasis-torchrl
eval`` select with it), :mod:`~oasis_torchrl.evaluation.rollouts` (rollouts to episodes, the
frames-only reward scored beside), :mod:`~oasis_torchrl.evaluation.recorders` (rerun and
LeRobot recordings), :mod:`~oasis_torchrl.evaluation.evaluator` (the :class:`Evaluator`) and
:mod:`~oasis_torchrl.evaluation.side_by_side` (policies recorded side by side). The package
stands on the envs, drivers, models, rewards and client; the training pipelines and the
commands stand on it.

>>> from oasis_torchrl.evaluation import EpisodeResult, EvalReport, selection_figure
>>> selection_figure(EvalReport([EpisodeResult("urban", 1, 42.0, False, 3.0, 9)]).to_dict())
42.0
"""

from oasis_torchrl.evaluation.evaluator import Evaluator
from oasis_torchrl.evaluation.recorders import EpisodeRecorders
from oasis_torchrl.evaluation.reports import (
    FRAMES_ONLY_NOTE,
    EpisodeResult,
    EvalReport,
    load_report,
)
from oasis_torchrl.evaluation.rollouts import ReferenceScore, episode_results, rollout_episodes
from oasis_torchrl.evaluation.selection import (
    beats,
    difference,
    paired_difference,
    selection_figure,
    selection_key,
    unpaired_difference,
)
from oasis_torchrl.evaluation.side_by_side import evaluate_side_by_side, side_by_side_for

__all__ = [
    "FRAMES_ONLY_NOTE",
    "EpisodeRecorders",
    "EpisodeResult",
    "EvalReport",
    "Evaluator",
    "ReferenceScore",
    "beats",
    "difference",
    "episode_results",
    "evaluate_side_by_side",
    "load_report",
    "paired_difference",
    "rollout_episodes",
    "selection_figure",
    "selection_key",
    "side_by_side_for",
    "unpaired_difference",
]
