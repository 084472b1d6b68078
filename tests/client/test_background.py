"""The pool's background event loop: coroutines it cannot run are closed, never left unawaited."""

from __future__ import annotations

import gc
import warnings

import pytest

from oasis_torchrl.client.background import EventLoopThread


async def answer() -> int:
    return 42


def test_runs_a_coroutine() -> None:
    loop = EventLoopThread("test")
    try:
        assert loop.run(answer()) == 42
    finally:
        loop.stop()


def test_a_stopped_loop_closes_the_coroutine_it_refuses() -> None:
    loop = EventLoopThread("test")
    loop.stop()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(RuntimeError, match="closed"):
            loop.run(answer())
        gc.collect()
    assert not [warning for warning in caught if "never awaited" in str(warning.message)]
