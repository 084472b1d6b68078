"""Episodes driven in the page, into a LeRobot dataset, one finalized episode at a time.

Each episode gets its own :class:`~oasis_torchrl.data.LeRobotRecorder` (the one ``oasis-torchrl
record`` writes with: same features, same rows), which reopens the dataset to append, saves the
episode and finalizes the dataset when the episode is stopped. So a discarded episode, a closed
tab, a dropped connection or a killed server loses at most the episode still running: every
episode saved before it is finalized and readable. A running episode's rows wait in the
recorder's episode buffer and touch the dataset only when the episode is saved.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from tensordict import TensorDictBase

from oasis_torchrl.data import LeRobotRecorder
from oasis_torchrl.data.loading import is_dataset_root
from oasis_torchrl.web.messages import Refused

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Storage:
    """How episodes are stored (:class:`~oasis_torchrl.data.LeRobotRecorder`'s arguments)."""

    repo_id: str | None = None
    fps: float = 20.0
    image_size: tuple[int, int] | None = None
    vcodec: str = "h264"
    crf: float = 18


class EpisodeRecording:
    """Start, stop (save) and discard episodes of one driven session.

    Args:
        root: the dataset folder.
        storage: how episodes are stored.
        append: ``root`` may already hold a dataset to add episodes to.

    Raises:
        FileExistsError: ``root`` holds a dataset and ``append`` is false.

    Example:
        >>> import tempfile, torch
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisEnv("local", 1, all_frames=True, server=ServerConfig(width=64, height=48))
        >>> td = env.reset()
        >>> recording = EpisodeRecording(Path(tempfile.mkdtemp()) / "drives")
        >>> recording.start()
        >>> for _ in range(2):
        ...     td["action"] = torch.zeros(1, 4, 2)
        ...     td = env.step(td)
        ...     _ = recording.write(td)
        ...     td = td["next"]
        >>> recording.stop(), recording.saved
        (True, 1)
        >>> env.close()
    """

    def __init__(
        self, root: str | Path, storage: Storage | None = None, *, append: bool = False
    ) -> None:
        self.root = Path(root)
        self.storage = storage or Storage()
        if is_dataset_root(self.root) and not append:
            raise FileExistsError(
                f"{self.root} already holds a LeRobot dataset; pass append=true to add episodes"
            )
        self.saved = 0
        self.steps = 0
        """Steps (chunks) of the running episode so far."""
        self._recorder: LeRobotRecorder | None = None

    @property
    def recording(self) -> bool:
        """Whether an episode is running."""
        return self._recorder is not None

    def start(self) -> None:
        """Start an episode (its first row is the next step written).

        Raises:
            Refused: ``already_recording``.
        """
        if self._recorder is not None:
            raise Refused("already_recording", "an episode is running: stop or discard it first")
        storage = self.storage
        self._recorder = LeRobotRecorder(
            self.root,
            repo_id=storage.repo_id,
            fps=storage.fps,
            image_size=storage.image_size,
            vcodec=storage.vcodec,
            crf=storage.crf,
            append=True,
            max_episodes=1,
            keep_unfinished=True,
        )
        self.steps = 0
        logger.info("recording an episode into %s", self.root)

    def write(self, step: TensorDictBase) -> bool:
        """Add one env step (``[1]``, with its ``"next"``); returns whether it ended the episode
        (the world's done flag: the episode is then saved)."""
        if self._recorder is None:
            return False
        self.steps += 1
        if self._recorder.write(step.unsqueeze(-1)):
            self._close(save=True)
            return True
        return False

    def stop(self) -> bool:
        """Save the running episode; returns whether one was saved.

        Raises:
            Refused: ``not_recording``.
        """
        if self._recorder is None:
            raise Refused("not_recording", "no episode is running")
        return self._close(save=True)

    def discard(self) -> None:
        """Drop the running episode (the dataset keeps every episode saved before).

        Raises:
            Refused: ``not_recording``.
        """
        if self._recorder is None:
            raise Refused("not_recording", "no episode is running")
        self._close(save=False)

    def close(self) -> None:
        """Drop any running episode (the server is stopping, the driver left)."""
        if self._recorder is not None:
            self._close(save=False)

    def _close(self, *, save: bool) -> bool:
        recorder, self._recorder = self._recorder, None
        recorder.close(keep_unfinished=save)
        written = recorder.episodes_written
        self.saved += written
        logger.info(
            "%s the episode (%d saved this session)", "saved" if written else "dropped", self.saved
        )
        return written > 0
