"""Configs: dataclass schemas, YAML files, flags and key=value overrides, generated help."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from oasis_torchrl.cli import build_parser, main, parse_arguments
from oasis_torchrl.config import config_names, load_config, to_object
from oasis_torchrl.config.arguments import load_from_args
from oasis_torchrl.config.recording import RecordConfig
from oasis_torchrl.config.training import BCConfig

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", ["bc", "demo", "eval", "film", "ppo", "serve"])
def test_named_configs_load_and_check(name: str) -> None:
    assert name in config_names()
    type(to_object(load_config(name)))  # the dataclasses' own checks pass on the defaults


def test_overrides_apply_with_types() -> None:
    cfg = load_config("ppo", ["env.prompts=[urban,rural]", "optim.lr=1e-4", "resume=latest"])
    assert list(cfg.env.prompts) == ["urban", "rural"]
    assert cfg.optim.lr == pytest.approx(1e-4)
    assert cfg.resume == "latest"


def test_bad_settings_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(
        ValueError, match=r"optim\.lrr=1: unknown key 'optim\.lrr' \(did you mean 'lr'"
    ):
        load_config("ppo", ["optim.lrr=1"])
    with pytest.raises(ValueError, match=r"env\.num_envs=many: Value 'many'"):
        load_config("ppo", ["env.num_envs=many"])
    with pytest.raises(ValueError, match=r"^env\.num_envs must be an integer >= 1, got 0$"):
        load_config("ppo", ["env.num_envs=0"])
    with pytest.raises(ValueError, match="must look like key=value"):
        load_config("ppo", ["optim.lr"])
    with pytest.raises(ValueError, match="no config named 'nope'"):
        load_config("nope")
    bad_file = tmp_path / "bad.yaml"
    bad_file.write_text("optim: {lrate: 1}\n")
    with pytest.raises(ValueError, match=r"bad\.yaml: unknown key 'optim\.lrate'"):
        load_config("ppo", file=bad_file)


def test_commands_report_bad_settings(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    assert main(["train", "ppo", "optim.lrate=1"]) == 2
    assert main(["train", "bc"]) == 2  # no dataset.root
    # A folder without a dataset is named, not looked up online as local/<name>.
    missing = tmp_path / "drives"
    assert main(["train", "bc", "--dataset.root", str(missing)]) == 2
    assert f"{missing} is not a LeRobot dataset" in caplog.text
    assert main(["record", "--episodes", "3"]) == 2  # no --root


def test_the_log_level_holds_after_a_library_configured_logging() -> None:
    script = (
        "import logging\n"
        "logging.debug('a library logs at import')  # gives the root logger a WARNING handler\n"
        "from oasis_torchrl.cli import main\n"
        "main(['--log-level', 'INFO', 'eval', 'episodes=-1'])\n"
        "print(logging.getLevelName(logging.getLogger().level))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=120
    )
    assert done.stdout.split() == ["INFO"]
    assert "eval: bad settings" in done.stderr


def test_file_then_flags_then_overrides(tmp_path: Path) -> None:
    settings = tmp_path / "ppo.yaml"
    settings.write_text("seed: 5\noptim: {lr: 0.01}\n")
    parser = build_parser()
    argv = ["train", "ppo", "seed=1", "--config", str(settings), "--optim.lr", "0.02", "seed=2"]
    args = parse_arguments(parser, argv)
    assert (args.config, args.overrides) == (settings, ["seed=1", "seed=2"])
    cfg = load_from_args(args, args.schema)
    assert (cfg.seed, cfg.optim.lr) == (2, 0.02)
    for grid in ("8,12", "[8, 12]"):  # a list flag with or without its brackets
        argv = ["train", "bc", "--policy.pool-grid", grid]
        assert load_from_args(parse_arguments(parser, argv), BCConfig).policy.pool_grid == [8, 12]
    with pytest.raises(SystemExit):
        parse_arguments(parser, ["train", "ppo", "--nope"])


def test_short_flags_set_the_same_settings_as_dotted_keys() -> None:
    argv = ["record", "--root", "out", "--num-envs", "3", "--prompt", "rain", "--prompt", "fog",
            "--width", "96", "--image-size", "32x48", "--ray-address", "auto"]  # fmt: skip
    cfg = load_from_args(parse_arguments(build_parser(), argv), RecordConfig)
    assert (cfg.env.num_envs, list(cfg.env.prompts), cfg.env.server.width) == (
        3,
        ["rain", "fog"],
        96,
    )
    assert (list(cfg.image_size), cfg.ray.address) == ([32, 48], "auto")
    dotted = ["record", "--root", "out", "env.num_envs=3", "env.server.width=96"]
    same = load_from_args(parse_arguments(build_parser(), dotted), RecordConfig)
    assert (same.env.num_envs, same.env.server.width) == (3, 96)


def test_help_comes_from_the_dataclasses(capsys: pytest.CaptureFixture[str]) -> None:
    for command in (["serve"], ["record"], ["train", "ppo"]):
        with pytest.raises(SystemExit):
            main([*command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--vp9-cpu-used VP9_CPU_USED" in text and "libvpx speed 0-8 (default: 8)" in text
    assert "--num-envs NUM_ENVS" in text and "sets env.num_envs" in text
    assert "--optim.lr LR" in text and "(default: 0.0003)" in text


def test_each_setting_has_one_flag_and_required_ones_say_so(
    capsys: pytest.CaptureFixture[str],
) -> None:
    for command in (["serve-policy"], ["serve"], ["record"]):
        with pytest.raises(SystemExit):
            main([*command, "--help"])
    text = capsys.readouterr().out
    assert "--api-key API_KEYS" in text and "--input INPUTS" in text  # the aliases ...
    assert "--api-keys" not in text and "--inputs" not in text  # ... are their one flag
    assert "--num-envs" in text and "--env.num-envs" not in text
    assert "???" not in text
    assert "(required)" in " ".join(text.split())  # serve-policy's policy, record's root


def test_version_is_the_distributions(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["--version"])
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert capsys.readouterr().out.split() == ["oasis-torchrl", version]


def test_a_section_s_help_gives_its_own_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["train", "bc", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--optim.lr LR" in text and "(default: 0.001)" in text
    assert "experiment name (the logger's folder) (default: bc)" in text


def test_both_trainers_share_the_run_and_optimiser_sections() -> None:
    ppo, bc = load_config("ppo", ["seed=3", "resume=latest"]), load_config("bc", ["seed=3"])
    run = ["seed", "output_dir", "progress", "init_from", "resume"]
    assert [ppo[key] for key in run[:3]] == [3, "outputs/ppo", True]
    assert [bc[key] for key in run[:3]] == [3, "outputs/bc", True]
    assert ppo.resume == "latest" and bc.init_from is None
    assert set(bc.optim) < set(ppo.optim)  # PPO's adds its own rates and schedule


def test_a_config_saved_before_the_optimiser_section_loads(tmp_path: Path) -> None:
    """Configs saved by the previous release spell BC's optimiser on its policy."""
    saved = tmp_path / "config.yaml"
    old = {"bc": {"policy": {"optimizer_lr": 0.002, "optimizer_grad_clip_norm": 5.0}}}
    OmegaConf.save(OmegaConf.create(old), saved)
    cfg = load_config("demo", file=saved)
    assert (cfg.bc.optim.lr, cfg.bc.optim.max_grad_norm, cfg.bc.optim.weight_decay) == (
        0.002,
        5.0,
        1.0e-4,
    )
    assert load_config("bc", ["policy.optimizer_weight_decay=0"]).optim.weight_decay == 0


def test_saved_config_loads_back(tmp_path: Path) -> None:
    cfg = load_config("demo", [f"output_dir={tmp_path}", "ppo.optim.lr=0.001"])
    saved = tmp_path / "config.yaml"
    OmegaConf.save(cfg, saved)
    assert load_config("demo", file=saved) == cfg
