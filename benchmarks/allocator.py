"""Training steps with glibc's default mmap threshold vs :func:`keep_batches_in_heap`.

The setting is process-wide and cannot be undone (once fixed, glibc no longer adapts the
threshold), so each side runs in its own child process of this script, alternating, on the same
data: a behaviour-cloning step of the main job (``bc_step.py``'s trainer: 8 autopilot drives of
40 chunks, batch 64, 64x96 frames) and a PPO update (``ppo_update.py``'s: our loss on a
minibatch of 128). Best of ``--repeats`` runs per child, best over ``--rounds`` children per
side.

Usage: ``python benchmarks/allocator.py [--rounds 2 --steps 40 --repeats 3]``; prints JSON with
milliseconds per step, the page faults taken while timing, and ``speedup`` (the default's over
ours; > 1: ours is faster, or faults less).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import torch

from oasis_torchrl.allocator import keep_batches_in_heap

SIDES = ("glibc_default", "keep_batches_in_heap")


def child(side: str, dataset: Path, steps: int, repeats: int) -> dict[str, float]:
    """Milliseconds of a BC step and a PPO update in this process, after ``side``'s setting,
    and the process's page faults while timing them (the mechanism, free of timing noise)."""
    if side == SIDES[1]:
        keep_batches_in_heap()
    import bc_step
    import ppo_update

    from oasis_torchrl.models import make_actor_critic
    from oasis_torchrl.train.ppo_loss import DrivingPPOLoss

    torch.manual_seed(0)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    with tempfile.TemporaryDirectory() as scratch:
        bc = bc_step.trainer(dataset, Path(scratch), [64, 96], steps)
        bc_ms = bc_step.ms_per_step(bc, repeats)
    net = ppo_update.trainer_network()
    loss = DrivingPPOLoss(make_actor_critic(net), aux_coeff=1.0)
    batch = ppo_update.minibatch(net, 128)
    ppo_ms = ppo_update.ms_per_step(loss, loss.terms, net, batch, repeats)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
    return {"bc_step_ms": bc_ms, "ppo_update_ms": ppo_ms, "page_faults": faults}


def run_child(side: str, dataset: Path, args: argparse.Namespace) -> dict[str, float]:
    """:func:`child` in a fresh interpreter (the setting cannot be undone in this one)."""
    command = [
        sys.executable,
        __file__,
        "--child",
        side,
        "--dataset",
        str(dataset),
        "--steps",
        str(args.steps),
        "--repeats",
        str(args.repeats),
    ]
    output = subprocess.run(command, check=True, capture_output=True, text=True).stdout
    return json.loads(output.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2, help="child processes per side")
    parser.add_argument("--steps", type=int, default=40, help="BC steps per timed run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--child", choices=SIDES, help=argparse.SUPPRESS)
    parser.add_argument("--dataset", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.dataset, args.steps, args.repeats)))
        return
    import bc_step

    with tempfile.TemporaryDirectory() as scratch:
        dataset = bc_step.record(Path(scratch) / "drives", episodes=8, steps=40)
        best: dict[str, dict[str, float]] = {side: {} for side in SIDES}
        for _ in range(args.rounds):
            for side in SIDES:
                for key, value in run_child(side, dataset, args).items():
                    best[side][key] = min(best[side].get(key, float("inf")), value)
    baseline, ours = best[SIDES[0]], best[SIDES[1]]
    report = {
        "threads": torch.get_num_threads(),
        **{side: {key: round(value, 1) for key, value in best[side].items()} for side in SIDES},
        "speedup": {key: round(baseline[key] / ours[key], 2) for key in baseline},
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
