"""The README's pictures (``docs/assets/*.png``) are what the code makes: the embedded server's
three cameras after an autopilot drive, and the top-down view of the same moment drawn from the
scene the server reports (``viz.topdown``, the layers rerun shows).

``OASIS_REGENERATE_ASSETS=1`` rewrites the pictures instead of checking them.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageDraw

from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.viz.topdown import (
    CAR_COLOR,
    DEFAULT_WINDOW,
    PATH_COLOR,
    PATH_RADIUS,
    ROAD_COLOR,
    Capsules,
    RoadMap,
    car_capsule,
    car_frame,
)

from ._hooks import ROOT

ASSETS = ROOT / "docs" / "assets"
REGENERATE = os.environ.get("OASIS_REGENERATE_ASSETS") == "1"
PROMPT, SEED, STEPS = "urban street", 3, 24
FRAME = (160, 240)  # (height, width) of each camera
PIXELS_PER_METRE = 5.0
GROUND = (46, 70, 52)
# Rendering may differ by rounding between machines; a different scene differs by far more.
MAX_MEAN_DIFFERENCE = 2.0


def _draw_strip(draw: ImageDraw.ImageDraw, points: np.ndarray, radius: float, color) -> None:
    """A line of ``radius`` metres through view points ``[K, 2]``, round at the ends."""
    pixels = [tuple(p) for p in _to_pixels(points)]
    width = max(1, round(2 * radius * PIXELS_PER_METRE))
    if len(pixels) > 1:
        draw.line(pixels, fill=tuple(color), width=width, joint="curve")
    for x, y in (pixels[0], pixels[-1]):
        r = width / 2
        draw.ellipse((x - r, y - r, x + r, y + r), fill=tuple(color))


def _to_pixels(points: np.ndarray) -> np.ndarray:
    origin = np.array([DEFAULT_WINDOW.x_range[0], DEFAULT_WINDOW.y_range[0]])
    return (points - origin) * PIXELS_PER_METRE


def _draw_capsules(draw: ImageDraw.ImageDraw, capsules: Capsules) -> None:
    for ends, radius, color in zip(capsules.ends, capsules.radii, capsules.colors, strict=True):
        _draw_strip(draw, ends, float(radius), color)


def topdown_image(road: RoadMap, path: np.ndarray, heading: float) -> Image.Image:
    """The top-down view of the car at the last point of world ``path`` ``[T, 2]``."""
    car = path[-1]
    size = (
        round(2 * DEFAULT_WINDOW.half_width * PIXELS_PER_METRE),
        round((DEFAULT_WINDOW.ahead + DEFAULT_WINDOW.behind) * PIXELS_PER_METRE),
    )
    image = Image.new("RGB", size, GROUND)
    draw = ImageDraw.Draw(image)
    view = road.view(car, heading)
    for strip in view.road:
        _draw_strip(draw, strip, view.road_radius, ROAD_COLOR)
    for strip, radius, color in zip(
        view.markings, view.marking_radii, view.marking_colors, strict=True
    ):
        _draw_strip(draw, strip, radius, color)
    _draw_capsules(draw, view.obstacles)
    _draw_strip(draw, car_frame(path, car, heading), PATH_RADIUS, PATH_COLOR)
    _draw_capsules(draw, car_capsule(road.car_size, CAR_COLOR))
    return image


def make_pictures() -> dict[str, Image.Image]:
    """Drive the autopilot on the embedded server; picture the cameras and the map."""
    env = OasisEnv(
        "local",
        num_envs=1,
        prompts=PROMPT,
        server=ServerConfig(width=FRAME[1], height=FRAME[0]),
        expert=True,
        max_steps=STEPS,
    )
    try:
        env.set_seed(SEED)
        rollout = env.rollout(STEPS, Autopilot())
        scene = env.scene_source()(PROMPT, int(rollout["episode_seed"][0, 0]))
    finally:
        env.close()
    last = rollout["next"][0, -1]
    cameras = np.concatenate(
        [last["pixels", camera].numpy() for camera in ("left_forward", "front", "right_forward")],
        axis=1,
    )
    truth = rollout["next", "truth"][0]
    path = np.stack([truth["x"].flatten(), truth["y"].flatten()], -1).astype(np.float64)
    heading = float(truth["heading"][-1, -1])
    assert scene is not None, "the embedded server reports its scenes"
    return {
        "cameras.png": Image.fromarray(cameras),
        "topdown.png": topdown_image(RoadMap.from_scene(scene), path, heading),
    }


@pytest.fixture(scope="module")
def pictures() -> dict[str, Image.Image]:
    return make_pictures()


@pytest.mark.parametrize("name", ["cameras.png", "topdown.png"])
def test_committed_picture_is_what_the_code_makes(
    pictures: dict[str, Image.Image], name: str
) -> None:
    made = pictures[name]
    path: Path = ASSETS / name
    if REGENERATE:
        ASSETS.mkdir(parents=True, exist_ok=True)
        made.save(path, optimize=True)
    assert path.is_file(), f"{path} is missing: run this test with OASIS_REGENERATE_ASSETS=1"
    committed = np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)
    fresh = np.asarray(made, dtype=np.int16)
    assert committed.shape == fresh.shape, "regenerate with OASIS_REGENERATE_ASSETS=1"
    difference = np.abs(committed - fresh).mean()
    assert difference <= MAX_MEAN_DIFFERENCE, (
        f"{name} differs from what the code makes by {difference:.2f} levels on average: "
        "regenerate it with OASIS_REGENERATE_ASSETS=1"
    )


def test_the_pictures_show_a_scene(pictures: dict[str, Image.Image]) -> None:
    cameras = np.asarray(pictures["cameras.png"])
    assert cameras.shape == (FRAME[0], 3 * FRAME[1], 3)
    assert cameras.std() > 10  # a rendered scene, not a blank frame
    topdown = np.asarray(pictures["topdown.png"])
    assert (topdown == ROAD_COLOR).all(-1).any()  # the road
    assert (topdown == CAR_COLOR).all(-1).any()  # the car
