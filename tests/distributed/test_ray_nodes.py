"""Recording and PPO on a real two-node Ray cluster: each node in its own network namespace.

The drivers run inside the head's namespace, where the machine's hostname resolves to
127.0.1.1 (see :mod:`oasis_torchrl.distributed.namespace_cluster`): weight sync must use the
nodes' cluster addresses. Each node has one CPU, so two collectors of one CPU each land one per
node; the tests check it from the placement the collectors report.
"""

from __future__ import annotations

import os
import re
import signal
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from oasis_torchrl.distributed import complete_shards
from oasis_torchrl.distributed.namespace_cluster import (
    HEAD_ADDRESS,
    WORKER_ADDRESS,
    NamespaceCluster,
    unavailable_reason,
)

from ._settings import smoke_ppo

REASON = unavailable_reason()
pytestmark = [
    pytest.mark.cluster,
    pytest.mark.skipif(REASON is not None, reason=f"no network namespaces: {REASON}"),
]

SESSIONS, STEPS = 2, 2
RUN_TIMEOUT_S = 420.0
"""Bound of one driver run (a loaded 2-core machine runs two Ray nodes and their workers)."""
TEST_TIMEOUT_S = 2 * RUN_TIMEOUT_S + 300
"""Bound of one test: its runs, and starting (or restarting) the nodes first."""
RECORD = ["--width", "96", "--height", "64", "--max-steps", str(STEPS), "--batch-steps", "2"]
RECORD += ["--ray", "--collectors", "2", "--sessions-per-env", str(SESSIONS)]
NOISE = ("was never awaited", "KeyError: '/mp-", "Traceback")
"""What a clean run never prints: unawaited coroutines, resource-tracker errors, tracebacks."""
PLACED = re.compile(r"collectors placed in [\d.]+s: (.*)")


@pytest.fixture(scope="module")
def cluster() -> Iterator[NamespaceCluster]:
    """Head and worker node, one CPU each, for every test of this module."""
    with NamespaceCluster(f"rn{os.getpid()}") as started:
        yield started


def oasis(*args: str) -> list[str]:
    """A driver command: ``oasis-torchrl ARGS``, logging at INFO."""
    return [sys.executable, "-m", "oasis_torchrl", "--log-level", "INFO", *args]


def placement(output: str) -> dict[int, str]:
    """Collector index -> node address, from the driver's placement line."""
    found = PLACED.search(output)
    assert found, output[-3000:]
    pairs = (item.split(" on ") for item in found.group(1).split(", "))
    return {int(index): node for index, node in pairs}


def assert_clean(output: str) -> None:
    for noise in NOISE:
        assert noise not in output, output[-4000:]


def episodes_in(root: Path) -> torch.Tensor:
    """The episode index of every row of the dataset at ``root``, read back with LeRobot."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = LeRobotDataset("local/drives", root=root, video_backend="pyav")
    assert dataset[len(dataset) - 1]["observation.images.front"].shape == (3, 64, 96)
    return torch.as_tensor(dataset.hf_dataset["episode_index"])


@pytest.mark.timeout(TEST_TIMEOUT_S)
def test_the_hostname_resolves_to_loopback_inside_the_nodes(cluster: NamespaceCluster) -> None:
    resolved = cluster.run(
        [sys.executable, "-c", "import socket; print(socket.gethostbyname(socket.gethostname()))"],
        timeout=60,
    )
    assert resolved.stdout.split() == ["127.0.1.1"]


@pytest.mark.timeout(TEST_TIMEOUT_S)
def test_ppo_weight_sync_reaches_collectors_on_both_nodes(
    cluster: NamespaceCluster, tmp_path: Path
) -> None:
    from oasis_torchrl.models.checkpoint import LATEST, load_checkpoint

    cluster.revive()
    settings = [*smoke_ppo(tmp_path), f"ray.address={cluster.address}"]
    run = cluster.run(oasis("train", "ppo", *settings), timeout=RUN_TIMEOUT_S)
    assert run.returncode == 0, run.stdout[-4000:]
    assert sorted(placement(run.stdout).values()) == [HEAD_ADDRESS, WORKER_ADDRESS]
    (checkpoint,) = tmp_path.rglob(LATEST)
    state = load_checkpoint(checkpoint)
    # two batches, each followed by an update whose weights reached both nodes before the next
    assert (state["iteration"], state["frames"]) == (2, 32)
    assert_clean(run.stdout)


@pytest.mark.timeout(TEST_TIMEOUT_S)
def test_recording_places_a_collector_on_each_node(
    cluster: NamespaceCluster, tmp_path: Path
) -> None:
    cluster.revive()
    root = tmp_path / "drives"
    command = ["record", "--root", str(root), "--episodes", "4", "--ray-address", cluster.address]
    run = cluster.run(oasis(*command, *RECORD), timeout=RUN_TIMEOUT_S)
    assert run.returncode == 0, run.stdout[-4000:]
    assert sorted(placement(run.stdout).values()) == [HEAD_ADDRESS, WORKER_ADDRESS]
    assert episodes_in(root).unique().tolist() == [0, 1, 2, 3]
    assert_clean(run.stdout)


def wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.2)


@pytest.mark.timeout(TEST_TIMEOUT_S)
@pytest.mark.parametrize("disruption", ["stop", "continue", "ctrl-c"])
def test_a_run_disrupted_mid_way(
    cluster: NamespaceCluster, tmp_path: Path, disruption: str
) -> None:
    """Once the worker node's collector finalized a shard part, either the worker node dies
    (``stop``: the lost worker named, what was finalized merged, exit 1; ``continue``: the head's
    collector records its whole share, exit 0) or the driver gets Ctrl-C (exit 130, what was
    finalized merged); every time the dataset reads back and the shutdown is quiet."""
    cluster.revive()
    root, shards, log = tmp_path / "drives", tmp_path / "shards", tmp_path / "driver.log"
    policy = "continue" if disruption == "continue" else "stop"
    command = ["record", "--root", str(root), "--episodes", "12", "--part-batches", "1"]
    command += ["--shard-root", str(shards), "--keep-shards", "--on-failure", policy]
    command += ["--ray-address", cluster.address, *RECORD]
    with log.open("w") as output:
        driver = cluster.popen(oasis(*command), output=output)
        try:
            wait_for(lambda: PLACED.search(log.read_text()), RUN_TIMEOUT_S, "the placement")
            remote = next(
                i for i, node in placement(log.read_text()).items() if node != HEAD_ADDRESS
            )
            first_part = shards / f"worker-{remote:03d}-part-0000"  # appears once finalized
            wait_for(first_part.is_dir, RUN_TIMEOUT_S, "the worker node's first shard part")
            if disruption == "ctrl-c":
                driver.send_signal(signal.SIGINT)
            else:
                cluster.kill_node(1)
            code = driver.wait(timeout=RUN_TIMEOUT_S)
        finally:
            if driver.poll() is None:
                os.killpg(driver.pid, signal.SIGKILL)
                driver.wait()
    text = log.read_text()
    assert code == {"stop": 1, "continue": 0, "ctrl-c": 130}[disruption], text[-4000:]
    finalized = [path.name for path in complete_shards(shards)]
    assert f"worker-{remote:03d}-part-0000" in finalized
    # every finalized part holds one batch: an episode per session
    assert episodes_in(root).unique().tolist() == list(range(len(finalized) * SESSIONS))
    if disruption != "ctrl-c":
        assert re.search(rf"worker\(s\) \[{remote}\] lost", text), text[-4000:]
    if disruption == "continue":
        head_parts = [name for name in finalized if not name.startswith(f"worker-{remote:03d}")]
        assert len(head_parts) * SESSIONS == 6  # the head's collector recorded its whole share
    assert "was never awaited" not in text and "KeyError: '/mp-" not in text


@pytest.mark.timeout(TEST_TIMEOUT_S)
@pytest.mark.parametrize(
    ("settings", "named"),
    [
        (["ray.address=10.77.0.9:6379"], "cannot reach the Ray cluster at 10.77.0.9:6379"),
        (["ray.num_collectors=3"], "could not place 3 collectors x {CPU: 1}"),
        (
            ["ray.resources_per_collector=[box=1]"],
            "could not place 2 collectors x {CPU: 1, box: 1}",
        ),
    ],
)
def test_what_the_cluster_cannot_do_fails_fast_by_name(
    cluster: NamespaceCluster, tmp_path: Path, settings: list[str], named: str
) -> None:
    cluster.revive()
    command = ["record", "--root", str(tmp_path / "drives"), "--episodes", "2", *RECORD]
    command += [f"ray.address={cluster.address}", "ray.startup_timeout_s=5", *settings]
    run = cluster.run(oasis(*command), timeout=RUN_TIMEOUT_S)
    assert run.returncode == 2, run.stdout[-4000:]
    assert named in run.stdout
    if "could not place" in named:
        assert f"2 alive nodes: {HEAD_ADDRESS} {{CPU: 1" in run.stdout
    assert not (tmp_path / "drives").exists()
