"""CPU time by process, for the benchmarks that run the embedded server in processes of its own.

Wall-clock rates on a shared machine move with everyone else's load; the CPU time each process
spent per unit of work does not (much), so the benchmarks report both. Linux only (``/proc``):
elsewhere the server's figures are None.

    >>> meter = CpuMeter(server_pid=None)
    >>> sum(range(10**5)) > 0
    True
    >>> sorted(meter.ms_per(1))
    ['front', 'this_process', 'total', 'workers']
"""

from __future__ import annotations

import os
import time
from pathlib import Path


def process_cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of process ``pid`` (all its threads); None without ``/proc``."""
    stat = Path(f"/proc/{pid}/stat")
    if not stat.exists():
        return None
    fields = stat.read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def child_pids(pid: int) -> list[int]:
    """Process ids of ``pid``'s children (a server's worker processes); empty without ``/proc``."""
    children = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(child) for child in children.read_text().split()] if children.exists() else []


class CpuMeter:
    """CPU seconds spent since construction by this process, a server process (its front) and
    the server's children (its workers).

    Args:
        server_pid: The server process, or None when the server runs in this process.
    """

    def __init__(self, server_pid: int | None) -> None:
        self._server = server_pid
        self._workers = [] if server_pid is None else child_pids(server_pid)
        self._started = self._now()

    def _now(self) -> dict[str, float | None]:
        front = None if self._server is None else process_cpu_seconds(self._server)
        workers = [process_cpu_seconds(pid) for pid in self._workers]
        return {
            "this_process": time.process_time(),
            "front": front,
            "workers": None if front is None or None in workers else sum(workers),
        }

    def ms_per(self, units: int) -> dict[str, float | None]:
        """CPU milliseconds per unit of work (e.g. per env step) of each part and in total."""
        now = self._now()
        spent = {
            part: None if now[part] is None or start is None else now[part] - start
            for part, start in self._started.items()
        }
        spent["total"] = sum(value for value in spent.values() if value is not None)
        return {
            part: None if value is None else round(1000 * value / units, 2)
            for part, value in spent.items()
        }
