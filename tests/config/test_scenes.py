"""The named scene sets (oasis_torchrl.config.scenes): what the embedded world reads from each
prompt, held-out scenes and seeds that no training or config uses, and the presets' copies."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from oasis_torchrl.config.presets import presets
from oasis_torchrl.config.reward_networks import MOTION_TRAINING_PROMPTS
from oasis_torchrl.config.scenes import (
    BROAD_TRAINING_PROMPTS,
    HELD_OUT_SCENES,
    HELD_OUT_SEEDS,
    LEARNING_HELD_OUT_SEED,
    REPORT_SEED,
    REWARD_CHECK_SEEDS,
)
from oasis_torchrl.sim.style import LAYOUTS, LIGHTINGS, WEATHERS, parse_style

ROOT = Path(__file__).resolve().parents[2]
BROAD_PRESETS = ("pretrained_clone", "pretrained_ppo_scratch")


def scene(prompt: str) -> tuple[str, str, str]:
    style = parse_style(prompt, np.random.default_rng(0))
    return style.layout, style.lighting, style.weather


def test_each_training_prompt_gets_the_layout_light_and_weather_it_names() -> None:
    for prompt in BROAD_TRAINING_PROMPTS:
        layout, lighting, weather = scene(prompt)
        named = prompt.replace("city", "urban")
        assert layout in named, prompt  # a keyword, not the fallback hash of the text
        assert (lighting == "day") == (lighting not in named), prompt
        assert (weather == "clear") == (weather not in named), prompt
    scenes = [scene(prompt) for prompt in BROAD_TRAINING_PROMPTS]
    assert len(set(scenes)) == len(scenes)
    assert {s[0] for s in scenes} == set(LAYOUTS)
    assert {s[1] for s in scenes} == set(LIGHTINGS)
    assert {s[2] for s in scenes} == set(WEATHERS)
    for layout in LAYOUTS:  # every weather and every lighting on every layout
        assert {s[2] for s in scenes if s[0] == layout} == set(WEATHERS), layout
        assert {s[1] for s in scenes if s[0] == layout} == set(LIGHTINGS), layout


def test_no_held_out_scene_is_a_training_combination() -> None:
    training = {scene(prompt) for prompt in BROAD_TRAINING_PROMPTS}
    held_out = [scene(prompt) for prompt in HELD_OUT_SCENES]
    assert len(set(held_out)) == len(HELD_OUT_SCENES) == 4
    assert not set(held_out) & training
    assert all(lighting != "day" and weather != "clear" for _, lighting, weather in held_out)


def test_the_motion_network_trains_on_no_held_out_scene_and_is_judged_on_unused_seeds() -> None:
    training = {scene(prompt) for prompt in MOTION_TRAINING_PROMPTS}
    assert not training & {scene(prompt) for prompt in HELD_OUT_SCENES}
    assert {s[1] for s in training} == set(LIGHTINGS) and {s[2] for s in training} == set(WEATHERS)
    assert not set(REWARD_CHECK_SEEDS) & {*HELD_OUT_SEEDS, LEARNING_HELD_OUT_SEED, REPORT_SEED}


def test_no_config_preset_or_benchmark_uses_the_held_out_seeds() -> None:
    assert LEARNING_HELD_OUT_SEED not in HELD_OUT_SEEDS
    scenes_module = ROOT / "oasis_torchrl" / "config" / "scenes.py"
    sources = [*(ROOT / "configs").glob("*.yaml"), *(ROOT / "benchmarks").glob("*.py")]
    sources += [p for p in (ROOT / "oasis_torchrl").rglob("*.py") if p != scenes_module]
    for seed in HELD_OUT_SEEDS:
        pattern = re.compile(rf"\b{seed}\b")
        assert not [p for p in sources if pattern.search(p.read_text())], seed


@pytest.mark.parametrize("name", BROAD_PRESETS)
def test_the_presets_train_on_the_broad_mix(name: str) -> None:
    preset = OmegaConf.load(presets()[name])
    assert list(preset.env.prompts) == list(BROAD_TRAINING_PROMPTS)
