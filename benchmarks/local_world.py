"""Env steps per second of ``OasisEnv("local")``: the old configuration against the default.

Both configurations step N rows at 96x64 with a constant throttle (rows that crash are reset,
as in training), in the same run, alternating:

- ``in_process_vp9``: the configuration before the multi-process server: the embedded server
  inside the stepping process, frames as VP9 (``ServerConfig(processes=0)``,
  ``frame_format="vp9"``);
- ``default``: a server process with its worker processes (one per core, at most one per row)
  and raw frames on loopback.

The same run measures the render-only ceiling of this machine: one process per core stepping
the simulator (physics and rendering of 4 frames x 3 cameras, nothing else) as fast as it can;
every configuration's figure is also given as a fraction of it. Env steps count rows: one
step of N rows is N env steps. Each case also reports the CPU milliseconds each process spent
per env step (the stepping process, the server's front and its workers): unlike the rates,
these hardly move with the machine's load. Prints JSON.

Run: ``python benchmarks/local_world.py [--seconds 10] [--sizes 1 8 16] [--repeats 1]``
"""

from __future__ import annotations

import argparse
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from typing import Any

import numpy as np
import torch
from _process_cpu import CpuMeter

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.simulator import Simulator

WIDTH, HEIGHT = 96, 64
PROMPT = "urban street"
THROTTLE = 0.5
WARMUP_STEPS = 3


def configurations() -> dict[str, dict[str, Any]]:
    """``OasisEnv`` keyword arguments of each configuration."""
    return {
        "in_process_vp9": {
            "server": ServerConfig(width=WIDTH, height=HEIGHT, processes=0),
            "frame_format": "vp9",
        },
        "default": {"server": ServerConfig(width=WIDTH, height=HEIGHT)},
    }


def env_steps_per_second(
    rows: int, seconds: float, **env_kwargs: Any
) -> tuple[float, dict[str, float | None]]:
    """Rows x steps per second of one env, crashed rows reset as they end, and the CPU
    milliseconds per env step of each process."""
    env = OasisEnv("local", rows, PROMPT, max_steps=10**6, **env_kwargs)
    try:
        env.set_seed(0)
        td = env.reset()
        action = torch.tensor([THROTTLE, 0.0]).expand(rows, 4, 2).clone()
        for _ in range(WARMUP_STEPS):
            _, td = env.step_and_maybe_reset(td.set("action", action))
        meter = CpuMeter(getattr(env.server, "pid", None))
        steps, started = 0, time.perf_counter()
        while time.perf_counter() - started < seconds:
            _, td = env.step_and_maybe_reset(td.set("action", action))
            steps += 1
        return rows * steps / (time.perf_counter() - started), meter.ms_per(rows * steps)
    finally:
        env.close()


def _render_only(seconds: float) -> int:
    """Simulator steps (render included) one process does in ``seconds``."""
    simulator = Simulator(WIDTH, HEIGHT)
    simulator.reset(PROMPT, seed=0)
    actions = np.tile(np.float32([THROTTLE, 0.0]), (4, 1))
    steps, started = 0, time.perf_counter()
    while time.perf_counter() - started < seconds:
        if simulator.step(actions).truth[-1].collided:
            simulator.reset(PROMPT, seed=steps)
        steps += 1
    return steps


def render_ceiling(seconds: float) -> float:
    """Simulator steps per second of one process per core, all at once."""
    cores = os.cpu_count() or 1
    with ProcessPoolExecutor(cores, mp_context=get_context("spawn")) as pool:
        list(pool.map(_render_only, [0.5] * cores))  # start and warm every process
        return sum(pool.map(_render_only, [seconds] * cores)) / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measuring time per case")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 8, 16], help="rows N")
    parser.add_argument("--repeats", type=int, default=1, help="measurements per case")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    ceilings = [render_ceiling(args.seconds)]
    names = list(configurations())
    rates: dict[str, dict[int, list[float]]] = {name: {n: [] for n in args.sizes} for name in names}
    cpu: dict[str, dict[int, list[dict]]] = {name: {n: [] for n in args.sizes} for name in names}
    for repeat in range(args.repeats):
        for rows in args.sizes:
            order = names if repeat % 2 == 0 else names[::-1]  # alternate: same load for both
            for name in order:
                rate, cpu_ms = env_steps_per_second(rows, args.seconds, **configurations()[name])
                rates[name][rows].append(rate)
                cpu[name][rows].append(cpu_ms)
    ceilings.append(render_ceiling(args.seconds))
    ceiling = float(np.mean(ceilings))
    results: dict[str, Any] = {}
    for rows in args.sizes:
        medians = {name: float(np.median(rates[name][rows])) for name in names}
        results[f"N={rows}"] = {
            **{f"{name}_env_steps_per_s": round(medians[name], 1) for name in names},
            **{f"{name}_all": [round(rate, 1) for rate in rates[name][rows]] for name in names},
            "default_over_in_process_vp9": round(medians["default"] / medians["in_process_vp9"], 2),
            **{f"{name}_fraction_of_ceiling": round(medians[name] / ceiling, 3) for name in names},
            **{f"{name}_cpu_ms_per_env_step": cpu[name][rows] for name in names},
        }
    default = {rows: results[f"N={rows}"]["default_env_steps_per_s"] for rows in args.sizes}
    report = {
        "benchmark": "local_world",
        "frame_size": f"{WIDTH}x{HEIGHT}",
        "cpus": os.cpu_count(),
        "seconds_per_case": args.seconds,
        "load_average_1min_before": round(load_before, 2),
        "render_only_ceiling_env_steps_per_s": round(ceiling, 1),
        "render_only_ceiling_before_after": [round(value, 1) for value in ceilings],
        "results": results,
        "default_largest_over_smallest": round(default[max(default)] / default[min(default)], 2),
        "targets": "N=8: default >= 2.5x in_process_vp9; default N=8 >= default N=1",
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
