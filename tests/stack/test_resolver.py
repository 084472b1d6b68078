"""pip's resolver accepts the project beside LeRobot 0.6.1 and the newest TorchRL release.

A user's environment has LeRobot and TorchRL pinned by themselves; the project (with its
plugin distribution) must install into it. ``pip install --dry-run`` resolves that set from the
package index without installing anything; the test is skipped only when the index cannot be
reached.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import oasis_torchrl

ROOT = Path(oasis_torchrl.__file__).parents[1]
LEROBOT = "0.6.1"
EXTRAS = "lerobot,rerun,depth,ray"
UNREACHABLE = (
    "NewConnectionError",
    "Failed to establish a new connection",
    "Temporary failure in name resolution",
    "Name or service not known",
    "Network is unreachable",
    "ConnectTimeoutError",
    "Read timed out",
)
"""What pip prints when it cannot reach the package index."""


def _pip(*args: str) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "pip", *args, "--retries", "1", "--timeout", "30"]
    env = {**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    result = subprocess.run(command, capture_output=True, text=True, timeout=900, env=env)
    if result.returncode != 0:
        signs = [line for line in result.stderr.splitlines() if any(s in line for s in UNREACHABLE)]
        if signs:
            pytest.skip(f"the package index is unreachable: {signs[0].strip()[:300]}")
    return result


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def newest_release(package: str) -> str:
    """The newest release of ``package`` on the package index."""
    result = _pip("index", "versions", package)
    assert result.returncode == 0, result.stderr[-2000:]
    return re.search(rf"^{package} \(([^)]+)\)", result.stdout, re.MULTILINE)[1]


def test_pip_resolves_the_project_with_lerobot_and_the_newest_torchrl(tmp_path: Path) -> None:
    torchrl = newest_release("torchrl")
    report = tmp_path / "report.json"
    result = _pip(
        "install",
        "--dry-run",
        "--ignore-installed",
        "--quiet",
        "--report",
        str(report),
        f"{ROOT}[{EXTRAS}]",
        str(ROOT / "policies"),
        f"lerobot=={LEROBOT}",
        f"torchrl=={torchrl}",
    )
    assert result.returncode == 0, (
        f"pip cannot install the project beside lerobot=={LEROBOT} and torchrl=={torchrl}:\n"
        + result.stderr[-3000:]
    )
    resolved = {
        _normalized(item["metadata"]["name"]): item["metadata"]["version"]
        for item in json.loads(report.read_text())["install"]
    }
    assert (resolved["lerobot"], resolved["torchrl"]) == (LEROBOT, torchrl)
    assert {"oasis-torchrl", "lerobot-policy-oasis"} <= set(resolved)
