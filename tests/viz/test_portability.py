"""The portable-API rule: our rerun code runs on rerun-sdk 0.26 up to the newest LeRobot allows.

Checked on the source (AST) of every module that talks to rerun: no deprecated or removed name,
no module-level logging function (they write to rerun's global recording), and only the
``RecordingStream`` methods that exist in all of them. Another rerun-sdk than the installed one
can be tried for real: ``pip install --target /tmp/rerun-other "rerun-sdk==0.26.*"`` then
``OASIS_RERUN_NEWEST_PATH=/tmp/rerun-other pytest tests/viz/test_portability.py``.
"""

from __future__ import annotations

import ast
import inspect
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import rerun as rr
import rerun.blueprint as rrb

import oasis_torchrl

PACKAGE = Path(oasis_torchrl.__file__).parent
SOURCES = [*sorted((PACKAGE / "viz").glob("*.py")), PACKAGE / "commands" / "view.py"]
BENCHMARK = PACKAGE.parent / "benchmarks" / "logging_overhead.py"
MODULE_ALIASES = {"rerun": rr, "rerun.blueprint": rrb}
REMOVED = {
    "set_time_sequence",
    "set_time_seconds",
    "set_time_nanos",
    "serve_web",
    "Scalar",
    "SeriesLine",
    "SeriesPoint",
    "TimeSequenceColumn",
    "TimeSecondsColumn",
    "TimeNanosColumn",
    "new_recording",
    "connect",
    "init",
}
"""Gone (or deprecated) in rerun-sdk releases after 0.26."""
PORTABLE_RECORDING_METHODS = {
    "log",
    "set_time",
    "send_columns",
    "send_blueprint",
    "save",
    "spawn",
    "connect_grpc",
    "flush",
    "disconnect",
}


def _rerun_uses(path: Path) -> tuple[list[tuple[object, str]], list[str]]:
    """(module, attribute) pairs used as ``rr.X`` / ``rrb.X``, and methods called on recordings."""
    tree = ast.parse(path.read_text(), filename=str(path))
    aliases: dict[str, object] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for name in node.names:
                if name.name in MODULE_ALIASES:
                    aliases[name.asname or name.name] = MODULE_ALIASES[name.name]
        elif isinstance(node, ast.ImportFrom) and node.module in MODULE_ALIASES:
            for name in node.names:
                aliases.setdefault(f"from:{name.name}", MODULE_ALIASES[node.module])
    module_uses = [
        (aliases[key], key.removeprefix("from:")) for key in aliases if key.startswith("from:")
    ]
    recording_methods = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        if isinstance(node.value, ast.Name) and node.value.id in aliases:
            module_uses.append((aliases[node.value.id], node.attr))
        elif ast.unparse(node.value).endswith("recording"):
            recording_methods.append(node.attr)
    return module_uses, recording_methods


def violations(path: Path) -> list[str]:
    """Every use of a rerun name that breaks the portable-API rule, described."""
    module_uses, recording_methods = _rerun_uses(path)
    found = []
    for module, name in module_uses:
        value = getattr(module, name, None)
        if name in REMOVED or value is None or getattr(value, "__deprecated__", None):
            found.append(f"{module.__name__}.{name} is removed, missing or deprecated")
        elif module is rr and (inspect.isfunction(value) or inspect.isbuiltin(value)):
            found.append(f"rr.{name} logs to rerun's global recording")
    for method in recording_methods:
        if method not in PORTABLE_RECORDING_METHODS:
            found.append(f"RecordingStream.{method} is not in the portable set")
    return found


@pytest.mark.parametrize("path", [*SOURCES, BENCHMARK], ids=lambda p: p.name)
def test_only_portable_rerun_api(path: Path) -> None:
    assert violations(path) == []


def test_the_rule_catches_deprecated_and_global_calls(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text(
        "import rerun as rr\n"
        "from rerun import Scalar\n"
        "recording = rr.RecordingStream('x')\n"
        "recording.set_time_sequence('frame', 1)\n"
        "rr.log('a', rr.TextLog('hi'))\n"
        "rr.serve_web()\n"
    )
    found = violations(bad)
    assert any("rerun.Scalar" in v for v in found)
    assert any("set_time_sequence" in v for v in found)
    assert any("rr.log logs to" in v for v in found)
    assert any("serve_web" in v for v in found)


NEWEST = os.environ.get("OASIS_RERUN_NEWEST_PATH")

_SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
import rerun
from viz._rollouts import rollout
from oasis_torchrl.viz import LogOptions, RolloutLogger
assert rerun.__version__ != {installed!r}, rerun.__file__
with RolloutLogger({out!r}, LogOptions(rows=(0, 1))) as rerun_logger:
    rerun_logger.log_rollout(rollout(2, 3, {{1: [1]}}))
print(rerun.__version__)
"""


@pytest.mark.skipif(NEWEST is None, reason="set OASIS_RERUN_NEWEST_PATH to another rerun-sdk")
def test_logging_runs_on_a_newer_rerun(tmp_path: Path) -> None:
    out = tmp_path / "newest.rrd"
    # rerun-sdk's wheel keeps the package under rerun_sdk/ (a .pth file adds it to the path).
    paths = [str(Path(NEWEST) / "rerun_sdk"), NEWEST, os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path for path in paths if path)}
    script = textwrap.dedent(_SCRIPT).format(
        tests=str(Path(__file__).parents[1]), out=str(out), installed=rr.__version__
    )
    run = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    stats = subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "stats", str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert stats.returncode == 0, stats.stderr
    assert (
        "env/1/camera/front"
        in subprocess.run(
            [sys.executable, "-m", "rerun", "rrd", "print", str(out)],
            env=env,
            capture_output=True,
            text=True,
            timeout=60,
        ).stdout
    )
