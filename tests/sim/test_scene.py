"""Prompt keywords to styles, determinism, and the rules every generated world keeps."""

from __future__ import annotations

import numpy as np
import pytest

from oasis_torchrl.sim.scene import CLEAR_START, build_scene
from oasis_torchrl.sim.style import LAYOUTS, parse_style


@pytest.mark.parametrize(
    ("prompt", "expected"),
    [
        ("Rainy CITY street at Night", ("urban", "night", "rain")),
        ("foggy highway", ("highway", "day", "fog")),
        ("snowy rural lane at sunset", ("rural", "sunset", "snow")),
        ("urban highway", ("urban", "day", "clear")),
    ],
)
def test_keywords_set_layout_lighting_weather(prompt: str, expected: tuple) -> None:
    style = parse_style(prompt, np.random.default_rng(0))
    assert (style.layout, style.lighting, style.weather) == expected


def test_any_text_gives_a_stable_valid_layout() -> None:
    layouts = {build_scene("a red balloon over a lake", seed).style.layout for seed in range(3)}
    assert len(layouts) == 1 and layouts <= set(LAYOUTS)
    assert build_scene("", 0).road.length > 3000


def test_same_prompt_and_seed_same_world_other_seed_other_world() -> None:
    first, again, other = (build_scene("urban", seed) for seed in (5, 5, 6))
    assert np.array_equal(first.road.y, again.road.y)
    assert np.array_equal(first.obstacles.x, again.obstacles.x)
    assert not np.array_equal(first.road.y, other.road.y)


def test_highway_has_more_lanes_than_rural() -> None:
    for seed in range(4):
        assert build_scene("highway", seed).style.lanes > build_scene("rural", seed).style.lanes


@pytest.mark.parametrize("prompt", ["urban", "highway", "rural"])
def test_start_is_clear_and_no_position_blocks_every_lane(prompt: str) -> None:
    scene = build_scene(prompt, 1)
    style, obstacles = scene.style, scene.obstacles
    on_road = np.abs(obstacles.d) < style.road_half_width
    assert obstacles.s[on_road].min() >= CLEAR_START
    lanes = np.array([style.lane_offset(lane) for lane in range(style.lanes)])
    for index in np.flatnonzero(on_road & (obstacles.s < 1500)):
        near = np.abs(obstacles.s - obstacles.s[index]) < 5.0
        reach = obstacles.half_across[near, None] + style.lane_width / 2
        blocked = np.any(np.abs(obstacles.d[near, None] - lanes) < reach, axis=0)
        assert not blocked.all(), f"every lane blocked near s={obstacles.s[index]:.1f}"


def test_road_coordinates_round_trip() -> None:
    road = build_scene("rural", 2).road
    s = np.linspace(0.0, 2000.0, 50)
    d = np.linspace(-6.0, 6.0, 50)
    x, y, _ = road.pose_at(s, d)
    located_s, located_d = road.locate(x, y, iterations=2)
    assert np.allclose(located_s, s, atol=0.05) and np.allclose(located_d, d, atol=0.02)
