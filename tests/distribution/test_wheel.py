"""The wheel works outside the source tree: package data, presets and .proto sources shipped,
configs load, the CLI runs.

The wheel is built from a copy of the distribution's files (the build writes ``build/`` and
``*.egg-info`` next to its sources) and installed with ``--no-deps`` into a scratch venv whose
``.pth`` file adds this interpreter's site-packages for the dependencies; that file is not a
site directory, so the development (editable) install inside it stays inactive and every
``oasis_torchrl`` import must come from the wheel. Everything runs from a folder outside the tree.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DISTRIBUTION_FILES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "LICENSE")
SHIPPED_FOLDERS = ("configs", "protos")
"""Top-level folders the wheel carries inside the package (setup.py)."""

PROTOS = ("a2v", "common", "policy", "sim")
SHIPPED_POLICY = ("config.json", "model.safetensors", "README.md", "curve.png", "card.json")
"""The files of a shipped policy's folder (a placeholder one is added to the built copy)."""

CHECK_INSTALLED = """
import sys
from pathlib import Path

import oasis_torchrl
from oasis_torchrl.config import config_names, load_config, to_object
from oasis_torchrl.config.presets import presets
from oasis_torchrl.drivers.pretrained import shipped_policies
from oasis_torchrl.proto import proto_sources

REQUIRED = {"import-recordings": ["source=in", "root=out"], "record": ["root=out"],
            "serve-policy": ["policy=in"], "view": ["path=in"]}

assert Path(oasis_torchrl.__file__).is_relative_to(sys.prefix), oasis_torchrl.__file__
print("version", oasis_torchrl.__version__)
print("protos", " ".join(sorted(proto_sources())))
for name in config_names():
    to_object(load_config(name, REQUIRED.get(name, [])))
    print("config", name)
for name, path in presets().items():
    assert Path(path).is_relative_to(sys.prefix), path
    print("preset", name)
for name, path in shipped_policies().items():
    assert Path(path).is_relative_to(sys.prefix), path
    print("policy", name)
"""


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A scratch venv with the freshly built wheel installed; returns its ``bin`` folder."""
    scratch = tmp_path_factory.mktemp("wheel")
    source = scratch / "source"
    shutil.copytree(
        ROOT / "oasis_torchrl",
        source / "oasis_torchrl",
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"),
    )
    for name in DISTRIBUTION_FILES:
        shutil.copy2(ROOT / name, source / name)
    for name in SHIPPED_FOLDERS:
        shutil.copytree(ROOT / name, source / name)
    placeholder = source / "oasis_torchrl" / "assets" / "policies" / "placeholder"
    placeholder.mkdir(parents=True, exist_ok=True)
    for name in SHIPPED_POLICY:
        (placeholder / name).write_text("placeholder\n")
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    dist = scratch / "dist"
    build = [*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(dist), str(source)]
    subprocess.run(build, check=True, capture_output=True, timeout=240)
    (wheel,) = dist.glob("oasis_torchrl-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    assert {f"oasis_torchrl/proto/{p}.proto" for p in PROTOS} <= names
    presets = {f"oasis_torchrl/configs/{path.name}" for path in (ROOT / "configs").glob("*.yaml")}
    assert presets and presets <= names
    assert any(name.endswith(".dist-info/licenses/LICENSE") for name in names)
    page = {f"oasis_torchrl/web/static/{name}" for name in ("index.html", "drive.js", "drive.css")}
    assert page <= names  # the drive page's assets
    policy = {f"oasis_torchrl/assets/policies/placeholder/{name}" for name in SHIPPED_POLICY}
    assert policy <= names  # a shipped policy's folder, its card included

    venv = scratch / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    Path(site, "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    install = [
        *pip,
        "--python",
        str(python),
        "install",
        "--no-deps",
        "--ignore-installed",
        "--no-index",
        str(wheel),
    ]
    # --ignore-installed: the development install's metadata is visible through the .pth file,
    # and pip would skip a wheel of the same version.
    subprocess.run(install, check=True, capture_output=True, timeout=240)
    assert Path(site, "oasis_torchrl", "proto", "sim.proto").is_file()
    return venv / "bin"


def _run_outside(command: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        command, cwd=cwd, env=env, capture_output=True, text=True, timeout=120, check=False
    )


def test_every_named_config_and_the_protos_load_from_the_wheel(
    installed: Path, tmp_path: Path
) -> None:
    result = _run_outside([str(installed / "python"), "-c", CHECK_INSTALLED], tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    lines = result.stdout.splitlines()
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert f"version {version}" in lines  # the wheel's metadata, not a source tree's fallback
    protos = [f"oasis_torchrl/proto/{name}.proto" for name in PROTOS]
    assert f"protos {' '.join(protos)}" in lines
    assert "policy placeholder" in lines  # pretrained:placeholder, found in the installed package
    shipped = {line.split()[1] for line in lines if line.startswith("preset ")}
    assert shipped == {path.stem for path in (ROOT / "configs").glob("*.yaml")}
    loaded = {line.split()[1] for line in lines if line.startswith("config ")}
    assert {
        "bc",
        "demo",
        "eval",
        "film",
        "import-recordings",
        "ppo",
        "record",
        "serve",
        "view",
    } <= loaded


def test_the_console_script_runs_from_the_wheel(installed: Path, tmp_path: Path) -> None:
    result = _run_outside([str(installed / "oasis-torchrl"), "--help"], tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    for command in ("train", "record", "eval", "view", "serve", "demo"):
        assert command in result.stdout
