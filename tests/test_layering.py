"""Imports flow one way, from the commands down to the protocol (the development guide's
"Layout" table). The evaluation package is a layer of its own: it stands on the envs and tools
(envs, drivers, data, viz, config) and the parts (client, models, rewards), and the training
pipelines and the commands stand on it. The embedded server is a peer of the client, on the
protocol alone."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "oasis_torchrl"
ABOVE_EVALUATION = {
    "__main__",
    "cli",
    "commands",
    "train",
    "distributed",
    "serving",
    "web",
    "film",
}
"""The entry points and the pipelines: evaluation never imports them."""
EVALUATION_IMPORTERS = {"commands", "train"}
"""What evaluates: the commands (``oasis-torchrl eval``) and the training pipelines."""


def imported_packages(path: Path) -> set[str]:
    """The ``oasis_torchrl`` packages and top-level modules ``path`` imports, lazily or not
    (``oasis_torchrl.envs.factory`` -> ``envs``).

    >>> sorted(imported_packages(PACKAGE / "evaluation" / "side_by_side.py"))
    ['drivers', 'evaluation', 'viz']
    """
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.ImportFrom) and node.module == "oasis_torchrl":
            names.update(f"oasis_torchrl.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return {name.split(".")[1] for name in names if name.startswith("oasis_torchrl.")}


def owner(path: Path) -> str:
    """The package (or top-level module) of ``oasis_torchrl`` that ``path`` belongs to."""
    return path.relative_to(PACKAGE).parts[0].removesuffix(".py")


def test_evaluation_imports_nothing_above_it() -> None:
    upward = {
        str(path.relative_to(PACKAGE)): sorted(imported_packages(path) & ABOVE_EVALUATION)
        for path in sorted((PACKAGE / "evaluation").rglob("*.py"))
    }
    assert not {path: names for path, names in upward.items() if names}


def test_only_the_commands_and_the_pipelines_import_evaluation() -> None:
    importers = {
        owner(path)
        for path in PACKAGE.rglob("*.py")
        if owner(path) != "evaluation" and "evaluation" in imported_packages(path)
    }
    assert importers <= EVALUATION_IMPORTERS, importers - EVALUATION_IMPORTERS


def loaded_by(*modules: str) -> list[str]:
    """The ``oasis_torchrl`` modules a fresh interpreter has loaded once it imported ``modules``."""
    code = (
        "import json, sys\n"
        f"import {', '.join(modules)}\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('oasis_torchrl.'))))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    return json.loads(result.stdout)


def test_importing_evaluation_loads_no_pipeline() -> None:
    loaded = {name.split(".")[1] for name in loaded_by("oasis_torchrl.evaluation")}
    assert "evaluation" in loaded and not loaded & ABOVE_EVALUATION


def test_the_server_side_imports_nothing_above_the_protocol() -> None:
    # The embedded server is a peer of the client: it stands on the protocol (and the ground
    # floor every layer shares: the settings fields, whole-file writes, the closing mixin and the
    # one-line video fallback of the package's import) alone; not even the config package.
    imported = loaded_by(
        "oasis_torchrl.sim.__main__", "oasis_torchrl.sim.launcher", "oasis_torchrl.sim.server"
    )
    allowed = ("oasis_torchrl.sim", "oasis_torchrl.proto", "oasis_torchrl.protocol")
    allowed += ("oasis_torchrl.options", "oasis_torchrl.atomic", "oasis_torchrl.closing")
    allowed += ("oasis_torchrl.video_fallback",)
    assert imported and not [name for name in imported if not name.startswith(allowed)]


def test_the_closing_mixin_imports_nothing_of_the_project() -> None:
    # A foundation: every layer, the embedded server included, may inherit it.
    assert imported_packages(PACKAGE / "closing.py") == set()
