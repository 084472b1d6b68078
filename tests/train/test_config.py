"""YAML configs with key=value overrides."""

from __future__ import annotations

import pytest

from oasis_torchrl.cli import main
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
