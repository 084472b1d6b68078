"""Retries, session loss, a killed and restarted server: the pool and the sync client cope."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np
import pytest

from oasis_torchrl.client import (
    ErrorCode,
    RetryPolicy,
    SequenceError,
    SessionLostError,
    SessionPool,
    SessionStatus,
    TransportError,
)
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer, ServerProcess

from ._helpers import FAST_RETRY, PROMPT, action_chunks, sync_rollout

SEEDS = [21, 22, 23, 24]
ZEROS = np.zeros((1, 4, 2), np.float32)


def test_flaky_server_delivers_every_frame_once(
    local_server: LocalServer,
    server_factory: Callable[..., LocalServer],
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="oasis_torchrl.client.retry")
    flaky = server_factory(failure_rate=0.3, failure_seed=7)
    chunks = action_chunks(3, 4, seed=9)
    with SessionPool(flaky.endpoint, 4, api_key=flaky.api_key, retry=FAST_RETRY) as pool:
        pool.prompt([PROMPT] * 4, seeds=SEEDS)
        steps = [pool.infer(chunk) for chunk in chunks]
    assert "Infer failed with UNAVAILABLE" in caplog.text  # faults really happened
    assert all(step.status.tolist() == [SessionStatus.OK] * 4 for step in steps)
    assert [step.sequence_nums.tolist() for step in steps] == [[k] * 4 for k in range(3)]
    with SessionPool(local_server.endpoint, 4, api_key=local_server.api_key) as pool:
        pool.prompt([PROMPT] * 4, seeds=SEEDS)
        for chunk, flaky_step in zip(chunks, steps, strict=True):
            clean_step = pool.infer(chunk)
            for name, frames in clean_step.frames.items():
                np.testing.assert_array_equal(flaky_step.frames[name], frames)
            np.testing.assert_array_equal(flaky_step.truth, clean_step.truth)
    flaky_sync = sync_rollout(flaky, SEEDS[0], chunks[:, 0], retry=FAST_RETRY)
    for k, chunk_frames in enumerate(flaky_sync):
        np.testing.assert_array_equal(chunk_frames["front"], steps[k].frames["front"][0])


def test_expired_session_restarts_only_its_row(
    server_factory: Callable[..., LocalServer],
) -> None:
    server = server_factory(idle_timeout_s=0.6)
    with SessionPool(server.endpoint, 3, api_key=server.api_key) as pool:
        pool.prompt([PROMPT] * 3, seeds=SEEDS[:3])
        pool.infer(np.zeros((3, 4, 2), np.float32))
        deadline = time.monotonic() + 1.4
        while time.monotonic() < deadline:  # rows 0 and 2 stay busy, row 1 idles out
            pool.infer(np.zeros((2, 4, 2), np.float32), indices=[0, 2])
            time.sleep(0.05)
        step = pool.infer(np.full((3, 4, 2), 0.5, np.float32))
        expected = [SessionStatus.OK, SessionStatus.RESTARTED, SessionStatus.OK]
        assert step.status.tolist() == expected, step.errors
        assert isinstance(step.errors[1], SessionLostError)
        assert step.errors[1].code == ErrorCode.INVALID_SESSION
        assert step.sequence_nums[1] == 0 and step.errors[0] is None
        restarted_front = step.frames["front"][1]
        again = pool.reset([1], [PROMPT], seeds=[SEEDS[1]])  # a clean start of the same world
        np.testing.assert_array_equal(restarted_front, again.frames["front"][0])
        assert pool.infer(np.zeros((3, 4, 2), np.float32)).status.tolist() == [0, 0, 0]


def test_sequence_desync_restarts_the_row(local_server: LocalServer) -> None:
    with SessionPool(local_server.endpoint, 2, api_key=local_server.api_key) as pool:
        pool.prompt([PROMPT] * 2, seeds=SEEDS[:2])
        pool.infer(np.zeros((2, 4, 2), np.float32))
        # Simulate a client that lost track of its rollout (e.g. a response dropped by a proxy).
        pool._runtime.sessions[0].state.sequence_num = 5
        step = pool.infer(np.full((2, 4, 2), 0.5, np.float32))
        assert step.status.tolist() == [SessionStatus.RESTARTED, SessionStatus.OK]
        assert isinstance(step.errors[0], SequenceError)
        assert step.sequence_nums.tolist() == [0, 1]


def wait_until_serving(pool: SessionPool, timeout: float = 20.0) -> None:
    """Poll the pool's health check until its channel has reconnected to the server."""
    deadline = time.monotonic() + timeout
    while not pool.ping():
        assert time.monotonic() < deadline, "the restarted server never became reachable"
        time.sleep(0.05)


def test_killed_server_fails_fast_and_a_restarted_one_recovers() -> None:
    policy = RetryPolicy(max_attempts=4, base_delay=0.05, max_delay=0.2, deadline=5.0)
    config = ServerConfig(width=96, height=64, api_keys=("kill-test-key",))
    server = ServerProcess(config).start()
    try:
        pool = SessionPool(server.endpoint, 2, api_key=server.api_key, retry=policy, timeout=5.0)
        with pool:
            pool.prompt([PROMPT] * 2, seeds=SEEDS[:2])
            pool.infer(np.zeros((2, 4, 2), np.float32))
            port = server.port
            server.kill()
            started = time.monotonic()
            with pytest.raises(TransportError) as raised:
                pool.infer(np.zeros((2, 4, 2), np.float32))
            assert time.monotonic() - started < 20.0  # a clear error, not a hang
            assert raised.value.row == 0 and raised.value.method in ("Infer", "Initialize")
            server = ServerProcess(config, port=port).start()
            wait_until_serving(pool)
            step = pool.infer(np.full((2, 4, 2), 0.4, np.float32))
            assert step.status.tolist() == [SessionStatus.RESTARTED] * 2
            assert step.sequence_nums.tolist() == [0, 0]
            pool.recover([1])
            step = pool.infer(np.zeros((2, 4, 2), np.float32))
            assert step.status.tolist() == [SessionStatus.OK] * 2
            assert step.sequence_nums.tolist() == [1, 0]
    finally:
        server.kill()


def test_unreachable_server_is_a_clear_error_at_start() -> None:
    pool = SessionPool("http://127.0.0.1:9", 2, api_key="k", timeout=0.5)
    with pytest.raises(TransportError, match=r"no connection within the 0\.5 s timeout"):
        pool.start()
    assert pool.session_ids == (None, None)
