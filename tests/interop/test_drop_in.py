"""The same script, written against the official API, behaves identically with our client.

Each SDK runs in its own subprocess: both register the same protobuf symbols, which clash in
one process's descriptor pool.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from oasis_torchrl.sim.launcher import LocalServer

SCRIPT = Path(__file__).with_name("official_api_script.py")


def run_script(sdk: str, server: LocalServer) -> dict:
    environment = {**os.environ, "DECART_API_KEY": server.api_key}
    completed = subprocess.run(
        [sys.executable, str(SCRIPT), "--sdk", sdk, "--endpoint", server.endpoint],
        capture_output=True,
        text=True,
        env=environment,
        timeout=120,
        check=False,
    )
    assert completed.returncode == 0, completed.stderr[-4000:]
    return json.loads(completed.stdout)


def test_official_script_gives_the_same_summary_with_both_sdks(local_server: LocalServer) -> None:
    pytest.importorskip("decart_oasis")
    official = run_script("decart_oasis", local_server)
    ours = run_script("oasis_torchrl.client", local_server)
    assert ours == official
    # The summary is only worth comparing if the script really exercised the service.
    assert official["wrong_key"] == {
        "kind": "A2VError",
        "code": 9,
        "message_is_str": True,
        "details_is_dict": True,
        "is_base": True,
    }
    assert official["infer_before_prompt"]["code"] == 7
    assert [v["kind"] for v in official["validation"]] == ["ValueError"] * 3
    assert official["missing_key"]["kind"] == official["missing_stream"]["kind"]
    assert [c["sequence_num"] for c in official["first_clip"]] == [0, 1, 2]
    first, again = official["first_clip"][0]["frames"], official["second_clip"][0]["frames"]
    assert first == again  # same prompt, seed and actions: same frames
    assert first["front"]["shapes"] == [[64, 96, 3]] and len(set(first["front"]["sha256"])) > 1
    assert official["consumer_events"].count("new_clip") == 2
    assert official["with_block_error"] == "'raised inside the with block'"
