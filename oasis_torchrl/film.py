"""A film: the autopilot driving one route on the embedded server, filmed by the three cameras.

:func:`film_route` starts the embedded A2V server, lets the privileged autopilot drive one
scripted route (a fixed prompt and seed) through the real protocol, writes the cameras side by
side to an MP4 and returns a summary.

"Drive" in this project means a policy or a person controlling the car through an env (the
drive loop of :mod:`oasis_torchrl.envs.driving`, :mod:`oasis_torchrl.drivers`, the drive page);
filming such a drive into a video is "film" (``oasis-torchrl film``).
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
class FilmSummary:
    """What the filmed drive did."""

    prompt: str
    seed: int
    steps: int
    frames: int
    distance_m: float
    progress_m: float
    collided: bool
    seconds: float
    video: str


def film_route(
    output: str | Path,
    *,
    prompt: str = "urban street, sunset",
    seed: int = 0,
    steps: int = 60,
    width: int = 768,
    height: int = 512,
) -> FilmSummary:
    """Film the autopilot driving ``steps`` chunks: write ``film.mp4`` + ``summary.json``.

    Example:
        >>> import tempfile
        >>> summary = film_route(tempfile.mkdtemp(), steps=3, width=96, height=64)
        >>> summary.frames
        16
    """
    output = Path(output)
    output.mkdir(parents=True, exist_ok=True)
    server = ServerConfig(width=width, height=height)
    env = OasisEnv("local", 1, prompt, server=server, all_frames=True, max_steps=steps, expert=True)
    pilot = Autopilot()
    started = time.perf_counter()
    taken = 0
    try:
        env.set_seed(seed)
        td = env.reset()
        with StripVideoWriter(output / "film.mp4", env.layout.cameras) as video:
            _write_frame(video, td, env.layout.cameras)
            for _ in tqdm(range(steps), desc="filmed drive", unit="step"):
                td = env.step(pilot(td))["next"]
                taken += 1
                _write_frame(video, td, env.layout.cameras)
                if td["done"].any():
                    break
            frames = video.frames_written
    finally:
        env.close()
    summary = FilmSummary(
        prompt=prompt,
        seed=seed,
        steps=taken,
        frames=frames,
        distance_m=round(float(td["truth", "distance"][0, -1]), 2),
        progress_m=round(float(td["truth", "progress"][0, -1]), 2),
        collided=bool(td["truth", "collided"][0, -1] > 0.5),
        seconds=round(time.perf_counter() - started, 2),
        video=str(output / "film.mp4"),
    )
    (output / "summary.json").write_text(json.dumps(asdict(summary), indent=2))
    return summary


def _write_frame(video: StripVideoWriter, td: TensorDictBase, cameras: tuple[str, ...]) -> None:
    video.write({camera: td["pixels", camera][0].numpy() for camera in cameras})
