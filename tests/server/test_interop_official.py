"""The official ``decart-oasis`` SDK (0.0.2) runs a full lifecycle against the embedded server.

The SDK runs in a subprocess (``tests/interop/official_lifecycle.py``): its generated protos
would clash with ours in protobuf's default descriptor pool inside one process.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from oasis_torchrl.sim.launcher import LocalServer

SCRIPT = Path(__file__).resolve().parents[1] / "interop" / "official_lifecycle.py"

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("decart_oasis") is None, reason="decart-oasis (dev extra) missing"
)


def test_official_client_lifecycle() -> None:
    with LocalServer(width=192, height=128) as server:
        completed = subprocess.run(
            [sys.executable, str(SCRIPT), server.endpoint],
            env={**os.environ, "DECART_API_KEY": server.api_key},
            capture_output=True,
            text=True,
            timeout=120,
        )
    assert completed.returncode == 0, completed.stderr
    report = json.loads(completed.stdout)
    assert report["streams"] == [
        [name, 192, 128] for name in ("left_forward", "front", "right_forward")
    ]
    assert report["session_target"] is True
    assert report["shapes"] == [
        [name, 4, 128, 192, 3] for name in sorted(("left_forward", "front", "right_forward"))
    ]
    assert report["sequence_nums"] == list(range(6))
    assert report["steering_difference"] > 2.0
    assert report["bad_key_code"] == 9
