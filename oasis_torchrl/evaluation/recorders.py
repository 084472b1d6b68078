"""Where evaluation episodes go besides the metrics: a rerun recording and/or a LeRobot dataset
(``eval.rerun``, ``eval.lerobot``), fed by the rollout's per-step hooks."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from tensordict import TensorDictBase

from oasis_torchrl.client import SceneLookup
from oasis_torchrl.evaluation.reports import EpisodeResult
from oasis_torchrl.evaluation.rollouts import NEXT

if TYPE_CHECKING:
    from oasis_torchrl.viz import RolloutLogger


class EpisodeRecorders:
    """Where evaluation episodes go besides the metrics: rerun and/or a LeRobot dataset.

    Args:
        rerun: an ``.rrd`` path, ``"spawn"`` or a viewer URL (needs the ``rerun`` extra), or a
            logger of a side-by-side recording (:mod:`oasis_torchrl.viz.side_by_side`).
        lerobot: a dataset folder; episodes are appended (one row per frame at 20 fps).
        scenes: the top-down view's scene source (``env.scene_source()``; None: car and path).
        name: the evaluated policy's name, which titles the panels of a recording made here.

    Example:
        >>> recorders = EpisodeRecorders()
        >>> recorders.close()
    """

    def __init__(
        self,
        rerun: str | RolloutLogger | None = None,
        lerobot: str | Path | None = None,
        scenes: SceneLookup | None = None,
        name: str = "",
    ) -> None:
        self.rerun = None
        self.lerobot = None
        if isinstance(rerun, str) and rerun:
            from oasis_torchrl.viz import RolloutLogger

            self.rerun = RolloutLogger(rerun, scenes=scenes, name=name)
        elif rerun:
            self.rerun = rerun
            if rerun.scenes is None:
                rerun.scenes = scenes
        if lerobot:
            from oasis_torchrl.data import LeRobotRecorder

            root = Path(lerobot)
            self.lerobot = LeRobotRecorder(root, append=(root / "meta").exists())

    def align(self, tick: int) -> None:
        """Start the next batch of episodes at ``tick`` of the recording (so the same batch
        starts at the same frame in every policy's recording)."""
        if self.rerun is not None:
            self.rerun.align(tick)

    def on_reset(self, td: TensorDictBase) -> None:
        """Log the reset observations."""
        if self.rerun is not None:
            self.rerun.log_reset(td)

    def on_step(self, td: TensorDictBase) -> None:
        """Log one step (``td`` holds the action and ``"next"``)."""
        if self.rerun is not None:
            self.rerun.log_step(td.get(NEXT), td.get("action"))

    def write_episodes(self, rollout: TensorDictBase, results: Sequence[EpisodeResult]) -> None:
        """Write each row's episode, up to its last step, to the LeRobot dataset."""
        if self.lerobot is None:
            return
        for row, result in enumerate(results):
            self.lerobot.write(rollout[row : row + 1, : result.steps])

    def close(self) -> None:
        """Finish the rerun recording and finalize the dataset."""
        if self.rerun is not None:
            self.rerun.close()
        if self.lerobot is not None:
            self.lerobot.close()
