"""A real Ray cluster on one machine: each node in its own Linux network namespace.

Two namespaces joined by a veth pair hold the cluster's only addresses (head
:data:`HEAD_ADDRESS`, worker :data:`WORKER_ADDRESS`); neither has a default route, so nothing
leaves the machine. Each node is a ``ray start`` inside its namespace and commands (the driver)
run inside one with :meth:`NamespaceCluster.run`. In both, the machine's hostname resolves to
127.0.1.1, as on Debian and Ubuntu hosts: ``ip netns exec`` mounts ``/etc/netns/<name>/hosts``
over ``/etc/hosts``, so a run that trusts the hostname cannot reach the other node. The
cluster uses Ray's token authentication with a token of its own (``RAY_AUTH_MODE=token`` and
``RAY_AUTH_TOKEN`` on every process). Used by the cluster tests and benchmarks; needs root and
iproute2 (:func:`unavailable_reason` says why not).
"""

from __future__ import annotations

import contextlib
import logging
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import IO

from oasis_torchrl.closing import Closing

logger = logging.getLogger(__name__)

HEAD_ADDRESS = "10.77.0.1"
WORKER_ADDRESS = "10.77.0.2"
PREFIX_LENGTH = 24
RAY_PORT = 6379
RAY_CLI = str(Path(sys.executable).parent / "ray")
"""Ray's command line of this interpreter's environment (a virtualenv need not be on PATH)."""
COMMAND_TIMEOUT_S = 180.0
"""Bound of every set-up command (``ip``, ``ray start``)."""
START_ATTEMPTS = 3
"""Starts of a node before giving up: Ray's own start-up deadlines can pass on a loaded machine
("The current node timed out during startup"), and a later start succeeds."""
STOP_GRACE_S = 10.0
"""How long the processes of a namespace get to exit on SIGTERM before SIGKILL."""
FAST_FAILURE_DETECTION = {
    # A node that stops answering is declared dead after about 3 s, not Ray's 30 s.
    "RAY_health_check_initial_delay_ms": "1000",
    "RAY_health_check_period_ms": "1000",
    "RAY_health_check_timeout_ms": "1000",
    "RAY_health_check_failure_threshold": "3",
    "RAY_USAGE_STATS_ENABLED": "0",
}
"""Environment of every node: quick node-failure detection, no usage reports."""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
    if check and done.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)} failed: {done.stderr.strip()}")
    return done


def unavailable_reason() -> str | None:
    """Why network namespaces cannot be made here (None: they can).

    Example:
        >>> unavailable_reason()  # doctest: +SKIP
        'network namespaces need root'
    """
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "iproute2's ip command is not installed"
    probe = f"oasis-probe-{os.getpid()}"
    made = _ip("netns", "add", probe, check=False)
    if made.returncode != 0:
        return f"cannot create a network namespace: {made.stderr.strip()}"
    _ip("netns", "delete", probe, check=False)
    return None


class NamespaceCluster(Closing):
    """A one- or two-node Ray cluster in network namespaces named after ``tag``.

    Args:
        tag: unique among concurrent clusters (e.g. with the process id): names the
            namespaces, the veth ends and the Ray temp folder.
        node_cpus: CPUs of each node: one entry (a head alone, the worker's namespace empty)
            or two (head and worker).
        object_store_memory: bytes of each node's object store.
        env: extra environment of the nodes and the commands run inside.

    Example:
        >>> with NamespaceCluster(f"doc{os.getpid()}") as cluster:  # doctest: +SKIP
        ...     cluster.run(["python", "-c", "import ray; ray.init(cluster.address)"]).returncode
        0
    """

    def __init__(
        self,
        tag: str,
        *,
        node_cpus: Sequence[int] = (1, 1),
        object_store_memory: int = 100 * 1024**2,
        env: Mapping[str, str] | None = None,
    ) -> None:
        if len(node_cpus) not in (1, 2):
            raise ValueError(f"node_cpus needs 1 or 2 entries, got {list(node_cpus)}")
        self.tag = tag
        self.node_cpus = list(node_cpus)
        self.object_store_memory = object_store_memory
        # Both namespaces and the link are made either way (a lone veth end has no carrier).
        self.namespaces = [f"{tag}-head", f"{tag}-work"]
        self.addresses = [HEAD_ADDRESS, WORKER_ADDRESS]
        token = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
        self.env = {**os.environ, **FAST_FAILURE_DETECTION, **token, **(env or {})}
        self.temp_dir = Path(tempfile.mkdtemp(prefix=f"ray-{tag}-", dir="/tmp"))  # short: sockets
        self._made: list[str] = []
        self.killed: set[int] = set()

    @property
    def address(self) -> str:
        """The cluster's address (the head's GCS), as ``ray.address`` takes it."""
        return f"{HEAD_ADDRESS}:{RAY_PORT}"

    def start(self) -> NamespaceCluster:
        """Make the namespaces and the link, then start the head and the worker node."""
        try:
            self._make_network()
            for node in range(len(self.node_cpus)):
                self._start_node(node)
        except BaseException:
            self.close()
            raise
        return self

    def _make_network(self) -> None:
        hosts = f"127.0.0.1 localhost\n127.0.1.1 {socket.gethostname()}\n"
        for namespace in self.namespaces:
            _ip("netns", "add", namespace)
            self._made.append(namespace)
            folder = Path("/etc/netns") / namespace
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "hosts").write_text(hosts)
            _ip("-n", namespace, "link", "set", "lo", "up")
        _ip("link", "add", f"{self.tag}-h", "type", "veth", "peer", "name", f"{self.tag}-w")
        for node, end in enumerate((f"{self.tag}-h", f"{self.tag}-w")):
            _ip("link", "set", end, "netns", self.namespaces[node])
            self._address(end, node)

    def _address(self, device: str, node: int) -> None:
        namespace = self.namespaces[node]
        address = f"{self.addresses[node]}/{PREFIX_LENGTH}"
        _ip("-n", namespace, "addr", "add", address, "dev", device)
        _ip("-n", namespace, "link", "set", device, "up")

    def _start_node(self, node: int) -> None:
        join = ["--head", f"--port={RAY_PORT}", "--include-dashboard=false"]
        if node:
            join = [f"--address={self.address}"]
        command = [
            RAY_CLI,
            "start",
            *join,
            f"--node-ip-address={self.addresses[node]}",
            f"--num-cpus={self.node_cpus[node]}",
            "--num-gpus=0",
            f"--object-store-memory={self.object_store_memory}",
            f"--temp-dir={self.temp_dir}",
            "--disable-usage-stats",
        ]
        for attempt in range(1, START_ATTEMPTS + 1):
            started = self.run(command, node=node, timeout=COMMAND_TIMEOUT_S)
            if started.returncode == 0:
                break
            self._stop_processes(node)  # what the failed start left behind
            if attempt == START_ATTEMPTS:
                raise RuntimeError(
                    f"ray start in {self.namespaces[node]} failed {attempt} times "
                    f"({started.returncode}): {started.stdout[-2000:]}"
                )
            logger.warning("ray start in %s failed; starting again", self.namespaces[node])
        logger.info("Ray node %s up in namespace %s", self.addresses[node], self.namespaces[node])

    def command(self, args: Sequence[str], *, node: int = 0) -> list[str]:
        """``args`` as a command run inside node ``node``'s namespace (0: the head)."""
        return ["ip", "netns", "exec", self.namespaces[node], *args]

    def run(
        self, args: Sequence[str], *, timeout: float, node: int = 0
    ) -> subprocess.CompletedProcess[str]:
        """Run ``args`` inside node ``node``'s namespace within ``timeout`` seconds; stdout and
        stderr together in ``stdout`` (a command past its time is killed, its output kept)."""
        process = self.popen(args, node=node)
        try:
            output, _ = process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            output, _ = process.communicate()
            output += f"\n[killed after {timeout:g}s]"
        return subprocess.CompletedProcess(process.args, process.returncode, output)

    def popen(
        self, args: Sequence[str], *, node: int = 0, output: IO[str] | None = None
    ) -> subprocess.Popen[str]:
        """Start ``args`` inside node ``node``'s namespace (its own process group), stdout and
        stderr to ``output`` (default: a pipe)."""
        return subprocess.Popen(
            self.command(args, node=node),
            env=self.env,
            stdout=output or subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )

    def pids(self, node: int) -> list[int]:
        """Every process inside node ``node``'s namespace."""
        listed = _ip("netns", "pids", self.namespaces[node], check=False)
        return [int(pid) for pid in listed.stdout.split()]

    def kill_node(self, node: int = 1) -> list[int]:
        """SIGKILL every process of node ``node`` (as a crashed machine); returns their PIDs."""
        pids = self.pids(node)
        for pid in pids:
            _signal(pid, signal.SIGKILL)
        self.killed.add(node)
        logger.info("killed node %s (%d processes)", self.addresses[node], len(pids))
        return pids

    def revive(self) -> None:
        """Start again every node :meth:`kill_node` killed (a new Ray node at its address)."""
        for node in sorted(self.killed):
            self._stop_processes(node)  # what the kill left (zombies, late children)
            self._start_node(node)
            self.killed.discard(node)

    def close(self) -> None:
        """Stop every process in the namespaces, delete them and the Ray temp folder."""
        for node in range(len(self._made)):
            self._stop_processes(node)
        for namespace in self._made:
            _ip("netns", "delete", namespace, check=False)
            shutil.rmtree(Path("/etc/netns") / namespace, ignore_errors=True)
        self._made = []
        shutil.rmtree(self.temp_dir, ignore_errors=True)

    def _stop_processes(self, node: int) -> None:
        pids = self.pids(node)
        for pid in pids:
            _signal(pid, signal.SIGTERM)
        deadline = time.monotonic() + STOP_GRACE_S
        while pids and time.monotonic() < deadline:
            time.sleep(0.2)
            pids = [pid for pid in pids if _alive(pid)]
        for pid in pids:
            _signal(pid, signal.SIGKILL)

    def __enter__(self) -> NamespaceCluster:
        return self.start()


def _signal(pid: int, number: signal.Signals) -> None:
    with contextlib.suppress(ProcessLookupError):  # exited meanwhile
        os.kill(pid, number)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"
