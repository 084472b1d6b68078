"""SessionPool against the real embedded server on loopback (96x64)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from oasis_torchrl.client import (
    JPEG,
    TRUTH_FIELDS,
    ErrorCode,
    FrameFormat,
    PermanentA2VError,
    SessionPool,
    SessionStatus,
)
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.sim.simulator import Simulator

from ._helpers import PROMPT, action_chunks, sync_rollout

STREAMS = ("left_forward", "front", "right_forward")
SEEDS = [3, 4, 5]


@pytest.fixture
def pool(local_server: LocalServer) -> SessionPool:
    with SessionPool(local_server.endpoint, 3, api_key=local_server.api_key) as started:
        yield started


def test_concurrent_steps_match_the_sync_client_frame_for_frame(
    local_server: LocalServer, pool: SessionPool
) -> None:
    assert pool.stream_names == STREAMS and pool.frame_size == (64, 96)
    assert len(set(pool.session_ids)) == 3
    chunks = action_chunks(3, 3)
    pool.prompt([PROMPT] * 3, seeds=SEEDS)
    steps = [pool.infer(chunk) for chunk in chunks]
    for k, step in enumerate(steps):
        assert step.status.tolist() == [SessionStatus.OK] * 3 and step.errors == [None] * 3
        assert step.sequence_nums.tolist() == [k] * 3
        assert step.truth.shape == (3, 4, len(TRUTH_FIELDS)) and not np.isnan(step.truth).any()
        for name in STREAMS:
            assert step.frames[name].shape == (3, 4, 64, 96, 3)
            assert step.frames[name].dtype == np.uint8 and step.frames[name].flags.c_contiguous
    for row, seed in enumerate(SEEDS):
        expected = sync_rollout(local_server, seed, chunks[:, row])
        for k, step in enumerate(steps):
            for name in STREAMS:
                np.testing.assert_array_equal(step.frames[name][row], expected[k][name])


def test_last_frame_pool_returns_exactly_the_last_frames(
    local_server: LocalServer, pool: SessionPool
) -> None:
    chunks = action_chunks(3, 3)
    with SessionPool(
        local_server.endpoint, 3, api_key=local_server.api_key, frames="last"
    ) as last_only:
        for full in (pool, last_only):
            full.prompt([PROMPT] * 3, seeds=SEEDS)
        for chunk in chunks:
            every, last = pool.infer(chunk), last_only.infer(chunk)
            for name in STREAMS:
                assert last.frames[name].shape == (3, 1, 64, 96, 3)
                np.testing.assert_array_equal(last.frames[name][:, 0], every.frames[name][:, -1])
    with pytest.raises(ValueError, match="frames must be one of"):
        SessionPool(local_server.endpoint, 1, frames="first")


def test_subsets_of_rows_step_independently(pool: SessionPool) -> None:
    pool.prompt([PROMPT] * 3, seeds=SEEDS)
    pool.infer(np.zeros((3, 4, 2), np.float32))
    step = pool.infer(np.full((2, 4, 2), 0.5, np.float32), indices=[2, 0])
    assert step.sequence_nums.tolist() == [1, 1] and step.frames["front"].shape[0] == 2
    step = pool.infer(np.zeros((1, 4, 2), np.float32), indices=[1])
    assert step.sequence_nums.tolist() == [1]
    speed = TRUTH_FIELDS.index("speed")
    assert step.truth[0, :, speed].max() == 0.0  # row 1 never got throttle


def test_reset_is_prompt_plus_one_chunk(local_server: LocalServer, pool: SessionPool) -> None:
    step = pool.reset([1, 2], [PROMPT, PROMPT], seeds=[8, 9])
    assert step.sequence_nums.tolist() == [0, 0]
    zero_chunk = np.zeros((1, 4, 2), np.float32)
    for j, seed in enumerate((8, 9)):
        expected = sync_rollout(local_server, seed, zero_chunk)[0]
        np.testing.assert_array_equal(step.frames["front"][j], expected["front"])
    actions = np.full((1, 4, 2), 0.3, np.float32)
    step = pool.reset([1], [PROMPT], actions=actions)
    np.testing.assert_array_equal(
        step.frames["front"][0], sync_rollout(local_server, 0, actions)[0]["front"]
    )


def test_resize_jpeg_and_stream_selection(local_server: LocalServer) -> None:
    with SessionPool(
        local_server.endpoint,
        2,
        api_key=local_server.api_key,
        accepted_formats=(JPEG,),
        resize=(32, 48),
        required_streams=("front",),
        decode_threads=2,
    ) as pool:
        assert pool.stream_names == ("front",) and pool.frame_size == (32, 48)
        step = pool.reset(None, [PROMPT] * 2, seeds=[1, 1])
        assert list(step.frames) == ["front"] and step.frames["front"].shape == (2, 4, 32, 48, 3)
        np.testing.assert_array_equal(step.frames["front"][0], step.frames["front"][1])


def test_depth_and_ping(pool: SessionPool) -> None:
    assert pool.ping() is True
    pool.reset(None, [PROMPT] * 3, seeds=SEEDS)
    depth = pool.depth(indices=[0, 2])
    assert sorted(depth) == sorted(STREAMS)
    assert all(d.shape == (2, 64, 96) and d.dtype == np.float32 for d in depth.values())


def test_bad_arguments_fail_locally_with_clear_errors(pool: SessionPool) -> None:
    with pytest.raises(ValueError, match="no prompt yet"):
        pool.infer(np.zeros((3, 4, 2), np.float32))
    pool.prompt([PROMPT] * 3)
    bad = np.zeros((3, 4, 2), np.float32)
    bad[1, 2, 0] = np.inf
    with pytest.raises(ValueError, match="actions for row 1 must be finite"):
        pool.infer(bad)
    with pytest.raises(ValueError, match=r"shape \(3, 4, 2\)"):
        pool.infer(np.zeros((3, 4), np.float32))
    with pytest.raises(ValueError, match="indices must be distinct"):
        pool.infer(np.zeros((2, 4, 2), np.float32), indices=[0, 3])
    with pytest.raises(ValueError, match="one prompt and one seed per selected row"):
        pool.prompt([PROMPT] * 2)
    with pytest.raises(ValueError, match="seed"):
        pool.prompt([PROMPT] * 3, seeds=[1, 2, -3])


def test_permanent_errors_name_the_row(local_server: LocalServer, pool: SessionPool) -> None:
    with pytest.raises(PermanentA2VError) as raised:
        pool.prompt([PROMPT, "   ", PROMPT])
    assert raised.value.code == ErrorCode.INVALID_REQUEST and raised.value.row == 1
    assert str(raised.value).startswith("session row 1:")
    wrong_key = SessionPool(local_server.endpoint, 2, api_key="wrong-key")
    with pytest.raises(PermanentA2VError) as raised:
        wrong_key.start()
    assert raised.value.code == ErrorCode.INVALID_API_KEY and raised.value.row == 0
    assert wrong_key.session_ids == (None, None)  # start is all or nothing


def test_a_pool_pickles_unstarted(local_server: LocalServer) -> None:
    pool = SessionPool(local_server.endpoint, 2, api_key=local_server.api_key, resize=(32, 48))
    clone = pickle.loads(pickle.dumps(pool))
    with clone:
        assert clone.start() == clone.streams  # idempotent
        assert clone.reset(None, [PROMPT] * 2).frames["front"].shape == (2, 4, 32, 48, 3)
        copy = pickle.loads(pickle.dumps(clone))  # a started pool arrives unstarted
        assert (copy.streams, copy.session_ids) == ((), (None, None))
    assert clone.session_ids == (None, None)


def test_on_this_machine_frames_travel_raw_exactly_as_rendered(local_server: LocalServer) -> None:
    chunks = action_chunks(2, 1)
    with SessionPool(local_server.endpoint, 1, api_key=local_server.api_key) as raw_pool:
        assert raw_pool.accepted_formats[0] == FrameFormat.RAW_RGB24
        raw_pool.reset(None, [PROMPT], seeds=[7])  # the Prompt and one all-zero chunk
        steps = [raw_pool.infer(chunk) for chunk in chunks]
    simulator = Simulator(96, 64)
    simulator.reset(PROMPT, 7)
    simulator.step(np.zeros((4, 2), np.float32))
    for chunk, step in zip(chunks, steps, strict=True):
        rendered = simulator.step(chunk[0]).rgb
        for name in STREAMS:  # no codec between the renderer and the pool: no loss
            np.testing.assert_array_equal(step.frames[name][0], rendered[name])
