"""Named presets (configs/*.yaml): each loads on its command, by name or by path."""

from __future__ import annotations

from pathlib import Path

import pytest
from omegaconf import OmegaConf

from oasis_torchrl.cli import main
from oasis_torchrl.config import load_config, to_object
from oasis_torchrl.config.presets import preset_file, preset_names, presets
from oasis_torchrl.protocol import DEFAULT_ENDPOINT, ENDPOINT_ENV_VAR

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = {
    "clone_256": ("demo", []),
    "demo": ("demo", []),
    "hosted": ("eval", []),
    "ppo_scratch": ("ppo", []),
    "pretrained_clone": ("demo", []),
    "pretrained_ppo_scratch": ("ppo", []),
    "serve": ("serve", []),
    "serve_policy": ("serve-policy", ["policy=policy.pt"]),
}
"""The command each preset is for, and the settings that command requires."""


def test_the_presets_are_the_top_level_folder() -> None:
    assert {path.parent for path in presets().values()} == {ROOT / "configs"}
    assert preset_names() == sorted(COMMANDS)


def _leaves(node: dict, prefix: str = "") -> list[str]:
    """The dotted keys of a nested mapping's values."""
    keys = []
    for key, value in node.items():
        keys += _leaves(value, f"{prefix}{key}.") if isinstance(value, dict) else [prefix + key]
    return keys


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_each_preset_loads_on_its_command_and_sets_only_what_differs(name: str) -> None:
    command, required = COMMANDS[name]
    cfg = load_config(command, required, file=name)
    to_object(cfg)  # the dataclasses' checks pass
    assert load_config(command, required, file=preset_file(name)) == cfg  # by path
    preset = OmegaConf.load(presets()[name])
    assert OmegaConf.merge(cfg, preset) == cfg  # the preset's values hold
    defaults = load_config(command, required)
    for key in _leaves(OmegaConf.to_container(preset)):  # each one a change
        assert OmegaConf.select(cfg, key) != OmegaConf.select(defaults, key), key


def test_the_scratch_recipe_turns_on_the_warmup_and_the_replay() -> None:
    cfg = load_config("ppo", file="ppo_scratch")
    assert cfg.warmup.frames > 0 and cfg.aux_replay.capacity > 0
    assert cfg.warmup.driver.startswith("constant:")


@pytest.mark.parametrize(
    ("name", "recipe", "command"),
    [("pretrained_ppo_scratch", "ppo_scratch", "ppo"), ("pretrained_clone", "clone_256", "demo")],
)
def test_a_shipped_policys_preset_is_its_recipe_on_the_broad_mix(
    name: str, recipe: str, command: str
) -> None:
    cfg = load_config(command, file=name)
    assert OmegaConf.merge(cfg, OmegaConf.load(presets()[recipe])) == cfg  # the recipe holds
    if command == "ppo":
        assert cfg.collector.total_frames == 204800 and cfg.checkpoint.keep_evaluated


def test_an_unknown_name_is_one_line_listing_the_names(caplog: pytest.LogCaptureFixture) -> None:
    assert main(["eval", "--config", "hostd"]) == 2
    (line,) = [record.getMessage() for record in caplog.records if "preset" in record.getMessage()]
    assert "no preset named 'hostd'; presets: clone_256, demo, hosted, ppo_scratch" in line
    assert "\n" not in line


def test_the_hosted_preset_takes_its_endpoint_from_the_environment(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """As ``A2VClient.from_env`` does: ``DECART_ROBOTICS_ENDPOINT``, else the hosted service;
    a flag or override still wins."""
    monkeypatch.delenv(ENDPOINT_ENV_VAR, raising=False)
    assert load_config("eval", file="hosted").env.endpoint == DEFAULT_ENDPOINT
    monkeypatch.setenv(ENDPOINT_ENV_VAR, "http://127.0.0.1:50051")
    assert load_config("eval", file="hosted").env.endpoint == "http://127.0.0.1:50051"
    overridden = load_config("eval", ["env.endpoint=http://10.0.0.2:1"], file="hosted")
    assert overridden.env.endpoint == "http://10.0.0.2:1"
    monkeypatch.setenv(ENDPOINT_ENV_VAR, "")
    with pytest.raises(ValueError, match="DECART_ROBOTICS_ENDPOINT set but empty"):
        load_config("eval", file="hosted")
