"""Worker processes: sessions spread over them, and a dead worker loses only its own sessions."""

from __future__ import annotations

import logging
import os
import signal
import time

import numpy as np
import pytest

from oasis_torchrl.client import SessionPool, SessionStatus
from oasis_torchrl.sim.launcher import LocalServer

ZERO = np.zeros((4, 4, 2), np.float32)
PROMPTS = ["urban street"] * 4


def test_a_killed_worker_ends_only_its_sessions(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    with (
        LocalServer(width=96, height=64, processes=2) as server,
        SessionPool(server.endpoint, 4, api_key=server.api_key) as pool,
    ):
        pool.reset(None, PROMPTS, seeds=[0, 1, 2, 3])
        assert (pool.infer(ZERO).status == SessionStatus.OK).all()
        victim = server.worker_pids[0]
        os.kill(victim, signal.SIGKILL)
        step = pool.infer(ZERO)
        restarted = np.flatnonzero(step.status == SessionStatus.RESTARTED)
        assert len(restarted) == 2 and (np.delete(step.status, restarted) == SessionStatus.OK).all()
        for row in restarted:
            assert f"worker process 0 (pid {victim}) killed by signal SIGKILL" in str(
                step.errors[row]
            )
        for _ in range(3):  # the restarted rows and the others all keep stepping
            assert (pool.infer(ZERO).status == SessionStatus.OK).all()
        with SessionPool(server.endpoint, 2, api_key=server.api_key) as more:  # new sessions
            assert (more.reset(None, PROMPTS[:2]).status == SessionStatus.OK).all()
        deadline = time.monotonic() + 30
        while server.worker_pids[0] == victim and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.worker_pids[0] != victim  # a fresh worker took its place
    assert f"server worker process 0 (pid {victim}) killed by signal SIGKILL" in caplog.text


def test_in_process_mode_runs_the_sessions_without_workers() -> None:
    with (
        LocalServer(width=96, height=64, processes=0) as server,
        SessionPool(server.endpoint, 2, api_key=server.api_key) as pool,
    ):
        assert server.worker_pids == []
        assert (pool.reset(None, PROMPTS[:2]).status == SessionStatus.OK).all()
