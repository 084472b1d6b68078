"""YAML configs with key=value overrides."""

from __future__ import annotations

from pathlib import Path

import pytest
from omegaconf import OmegaConf

from oasis_torchrl.cli import build_parser, main, parse_arguments
from oasis_torchrl.train.config import load_config


@pytest.mark.parametrize(
    ("name", "key"),
    [("ppo", "collector"), ("bc", "dataset"), ("eval", "policy"), ("demo", "record")],
)
def test_shipped_configs_load(name: str, key: str) -> None:
    assert key in load_config(name)


def test_overrides_apply_with_types() -> None:
    cfg = load_config("ppo", ["env.prompts=[urban,rural]", "optim.lr=1e-4", "resume=latest"])
    assert list(cfg.env.prompts) == ["urban", "rural"]
    assert cfg.optim.lr == pytest.approx(1e-4)
    assert cfg.resume == "latest"


def test_bad_overrides_name_the_problem() -> None:
    with pytest.raises(ValueError, match=r"unknown config key in override 'optim\.lrate=1'"):
        load_config("ppo", ["optim.lrate=1"])
    with pytest.raises(ValueError, match="must look like key=value"):
        load_config("ppo", ["optim.lr"])
    with pytest.raises(FileNotFoundError, match="config 'nope' not found"):
        load_config("nope")


def test_train_command_reports_bad_settings() -> None:
    assert main(["train", "ppo", "optim.lrate=1"]) == 2
    assert main(["train", "bc", "dataset.root=null"]) == 2


def test_overrides_may_follow_the_options(tmp_path: Path) -> None:
    config = tmp_path / "ppo.yaml"
    config.write_text(OmegaConf.to_yaml(load_config("ppo")))
    parser = build_parser()
    args = parse_arguments(parser, ["train", "ppo", "seed=1", "--config", str(config), "seed=2"])
    assert (args.config, args.overrides) == (config, ["seed=1", "seed=2"])
    with pytest.raises(SystemExit):
        parse_arguments(parser, ["train", "ppo", "--config", str(config), "--nope"])
    assert main(["train", "ppo", "--config", str(config), "optim.lrate=1"]) == 2
