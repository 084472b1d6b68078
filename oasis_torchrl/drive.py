"""A filmed drive: the autopilot on the embedded server, filmed by the three cameras.

:func:`drive_route` starts the embedded A2V server, drives one scripted route (a fixed prompt
and seed) with the privileged autopilot through the real protocol, writes the cameras side by
side to an MP4 and returns a summary.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from tensordict import TensorDictBase
from tqdm.auto import tqdm

from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.video import StripVideoWriter

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class DriveSummary:
    """What the demo drive did."""

    prompt: str
    seed: int
    steps: int
    frames: int
    distance_m: float
    progress_m: float
    collided: bool
    seconds: float
    video: str


def drive_route(
    output: str | Path,
    *,
    prompt: str = "urban street, sunset",
    seed: int = 0,
    steps: int = 60,
    width: int = 768,
    height: int = 512,
) -> DriveSummary:
    """Drive ``steps`` chunks with the autopilot and write ``drive.mp4`` + ``summary.json``.

    Example:
        >>> import tempfile
        >>> summary = drive_route(tempfile.mkdtemp(), steps=3, width=96, height=64)
        >>> summary.frames
        16
    """
    output = Path(output)
    output.mkdir(parents=True, exist_ok=True)
    server = ServerConfig(width=width, height=height)
    env = OasisEnv("local", 1, prompt, server=server, all_frames=True, max_steps=steps)
    pilot = Autopilot()
    started = time.perf_counter()
    taken = 0
    try:
        env.set_seed(seed)
        td = env.reset()
        with StripVideoWriter(output / "drive.mp4", env.layout.cameras) as video:
            _film(video, td, env.layout.cameras)
            for _ in tqdm(range(steps), desc="demo drive", unit="step"):
                td = env.step(pilot(td))["next"]
                taken += 1
                _film(video, td, env.layout.cameras)
                if td["done"].any():
                    break
            frames = video.frames_written
    finally:
        env.close()
    summary = DriveSummary(
        prompt=prompt,
        seed=seed,
        steps=taken,
        frames=frames,
        distance_m=round(float(td["truth", "distance"][0, -1]), 2),
        progress_m=round(float(td["truth", "progress"][0, -1]), 2),
        collided=bool(td["truth", "collided"][0, -1] > 0.5),
        seconds=round(time.perf_counter() - started, 2),
        video=str(output / "drive.mp4"),
    )
    (output / "summary.json").write_text(json.dumps(asdict(summary), indent=2))
    return summary


def _film(video: StripVideoWriter, td: TensorDictBase, cameras: tuple[str, ...]) -> None:
    video.write({camera: td["pixels", camera][0].numpy() for camera in cameras})
