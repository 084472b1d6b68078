"""Replaying a saved episode in the page: its stored frames, decoded from the dataset's videos and
sent at the dataset's fps as frame messages marked ``"replay": true``, then ``replay_done``."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from oasis_torchrl.data.features import image_key
from oasis_torchrl.data.loading import default_repo_id, is_dataset_root
from oasis_torchrl.data.video_frames import episode_frames
from oasis_torchrl.web.frames import pack_frames
from oasis_torchrl.web.messages import Refused

logger = logging.getLogger(__name__)

Send = Callable[[bytes | dict[str, Any]], Awaitable[None]]


class EpisodeReplay:
    """Streams saved episodes of the dataset at ``root`` to a page.

    Args:
        root: the dataset folder.
        repo_id: its LeRobot repo id (default ``local/<folder name>``).
        jpeg_quality: quality of the frames sent.
    """

    def __init__(self, root: str | Path, repo_id: str | None = None, jpeg_quality: int = 80):
        self.root = Path(root)
        self.repo_id = repo_id or default_repo_id(self.root)
        self.jpeg_quality = jpeg_quality

    def frames(self, episode: int) -> tuple[float, list[str], Iterator[dict[str, np.ndarray]]]:
        """``(fps, cameras, frames)`` of a saved episode: one ``camera -> frame`` per row.

        Raises:
            Refused: ``no_episode``: the dataset has no such episode (yet).
        """
        from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

        if not is_dataset_root(self.root):
            raise Refused("no_episode", f"no episode saved in {self.root} yet")
        meta = LeRobotDatasetMetadata(self.repo_id, root=self.root)
        if not 0 <= episode < meta.total_episodes:
            raise Refused(
                "no_episode", f"episode {episode} is not saved ({meta.total_episodes} episodes)"
            )
        cameras = [key.removeprefix(image_key("")) for key in meta.video_keys]
        streams = [episode_frames(meta, episode, key) for key in meta.video_keys]
        rows = (dict(zip(cameras, row, strict=True)) for row in zip(*streams, strict=True))
        return float(meta.fps), cameras, rows

    async def __call__(self, episode: int, send: Send) -> None:
        """Send episode ``episode`` to a page, paced at the dataset's fps."""
        loop = asyncio.get_running_loop()
        fps, cameras, rows = await loop.run_in_executor(None, self.frames, episode)
        count = 0
        while True:
            message = await loop.run_in_executor(None, self._next_message, rows, cameras, count)
            if message is None:
                break
            await send(message)
            count += 1
            await asyncio.sleep(1.0 / fps)
        await send({"type": "replay_done", "episode": episode, "frames": count})
        logger.info("replayed episode %d (%d frames)", episode, count)

    def _next_message(
        self, rows: Iterator[dict[str, np.ndarray]], cameras: list[str], index: int
    ) -> bytes | None:
        row = next(rows, None)
        if row is None:
            return None
        header = {"type": "frame", "replay": True, "frame": index, "seq": 0}
        return pack_frames(row, cameras, header, self.jpeg_quality)
