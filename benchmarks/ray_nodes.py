"""Ray across real nodes: recording throughput and PPO collection time, on clusters built from
network namespaces on this machine (:mod:`oasis_torchrl.distributed.namespace_cluster`; root).

- Recording: episodes per second of ``record --ray`` with two collectors on two one-CPU nodes
  against the same two collectors on one two-CPU node (same total CPUs), timed from the
  driver's placement line to its last line (start-up excluded).
- PPO: seconds per collected batch (the trainer's ``time/collect_s``, first batch excluded)
  with two remote collectors on the two-node cluster against one collector in the driver's
  process (no Ray) over the same number of sessions.

Prints JSON with both ratios. Every driver runs inside the head's namespace.

    python benchmarks/ray_nodes.py --episodes 16 --batches 4
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import os
import statistics
import subprocess
import sys
import tempfile
from datetime import datetime
from pathlib import Path
from typing import Any

from oasis_torchrl.distributed.namespace_cluster import NamespaceCluster, unavailable_reason

logger = logging.getLogger(__name__)

RUN_TIMEOUT_S = 1200.0


def oasis(*args: str) -> list[str]:
    return [sys.executable, "-m", "oasis_torchrl", "--log-level", "INFO", *args]


def _stamp(line: str) -> datetime:
    return datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f")


def recording_rate(node_cpus: tuple[int, ...], args: argparse.Namespace, work: Path) -> dict:
    """Episodes per second of a two-collector recording on a cluster of ``node_cpus``."""
    root = work / f"drives-{len(node_cpus)}"
    command = ["record", "--root", str(root), "--episodes", str(args.episodes)]
    command += ["--width", str(args.width), "--height", str(args.height)]
    command += ["--max-steps", str(args.max_steps), "--batch-steps", str(args.max_steps)]
    command += ["--ray", "--collectors", "2", "--sessions-per-env", str(args.sessions)]
    with NamespaceCluster(f"rb{os.getpid()}", node_cpus=node_cpus) as cluster:
        run = cluster.run(oasis(*command, "--ray-address", cluster.address), timeout=RUN_TIMEOUT_S)
    if run.returncode != 0:
        raise RuntimeError(f"recording on {node_cpus} failed: {run.stdout[-3000:]}")
    lines = [line for line in run.stdout.splitlines() if line[:2] == "20"]  # timestamped
    placed = next(line for line in lines if "collectors placed" in line)
    seconds = (_stamp(lines[-1]) - _stamp(placed)).total_seconds()
    return {
        "node_cpus": list(node_cpus),
        "placement": placed.split("collectors placed in ", 1)[1],
        "episodes": args.episodes,
        "seconds": round(seconds, 2),
        "episodes_per_s": round(args.episodes / seconds, 3),
    }


def ppo_collect_seconds(remote: bool, args: argparse.Namespace, work: Path) -> dict:
    """Median seconds per PPO batch collected, by remote collectors or in this process."""
    output = work / ("ppo-remote" if remote else "ppo-local")
    frames = 2 * args.sessions * args.batch_steps
    settings = [
        f"env.image_size=[{args.height},{args.width}]",
        f"env.server.width={args.width}",
        f"env.server.height={args.height}",
        f"output_dir={output}",
        f"collector.frames_per_batch={frames}",
        f"collector.total_frames={frames * (args.batches + 1)}",
        f"optim.mini_batch_size={frames}",
        "optim.epochs=1",
        "eval.every=0",
        "eval.episodes=0",
        "progress=false",
    ]
    if remote:
        settings += ["ray.enabled=true", "ray.num_collectors=2"]
        settings += [f"ray.sessions_per_env={args.sessions}"]
        with NamespaceCluster(f"rp{os.getpid()}") as cluster:
            settings.append(f"ray.address={cluster.address}")
            run = cluster.run(oasis("train", "ppo", *settings), timeout=RUN_TIMEOUT_S)
    else:
        settings += [f"env.num_envs={2 * args.sessions}"]
        run = subprocess.run(
            oasis("train", "ppo", *settings),
            capture_output=True,
            text=True,
            timeout=RUN_TIMEOUT_S,
        )
    if run.returncode != 0:
        raise RuntimeError(f"PPO ({'remote' if remote else 'local'}) failed: {run.stdout[-3000:]}")
    (table,) = output.rglob("collect_s.csv")
    with table.open() as file:
        seconds = [float(row[-1]) for row in csv.reader(file)][1:]  # the first batch warms up
    return {
        "collectors": "2 remote (one per node)" if remote else "in-process",
        "frames_per_batch": frames,
        "batches": len(seconds),
        "collect_s_per_batch": round(statistics.median(seconds), 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=16, help="episodes per recording")
    parser.add_argument("--sessions", type=int, default=2, help="sessions per collector")
    parser.add_argument("--max-steps", type=int, default=4, help="env steps per episode")
    parser.add_argument("--batches", type=int, default=4, help="timed PPO batches")
    parser.add_argument("--batch-steps", type=int, default=4, help="PPO steps per session")
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=64)
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO)
    reason = unavailable_reason()
    if reason is not None:
        raise SystemExit(f"cannot build the clusters: {reason}")
    with tempfile.TemporaryDirectory(prefix="ray-nodes-") as folder:
        work = Path(folder)
        measured = []
        for measure in (
            lambda: recording_rate((1, 1), args, work),
            lambda: recording_rate((2,), args, work),
            lambda: ppo_collect_seconds(True, args, work),
            lambda: ppo_collect_seconds(False, args, work),
        ):
            measured.append(measure())
            logger.info("measured %s", json.dumps(measured[-1]))  # kept if a later one fails
        two, one, remote, local = measured
    result: dict[str, Any] = {
        "recording_two_nodes": two,
        "recording_one_node": one,
        "recording_rate_ratio_two_vs_one": round(two["episodes_per_s"] / one["episodes_per_s"], 3),
        "ppo_remote": remote,
        "ppo_local": local,
        "ppo_collect_ratio_remote_vs_local": round(
            remote["collect_s_per_batch"] / local["collect_s_per_batch"], 3
        ),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
