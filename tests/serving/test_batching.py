"""The batcher: requests waiting together share one call within the row limit, and a call
that raises is re-run request by request so that only the culprit fails."""

from __future__ import annotations

import threading
import time

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.serving.batching import Batcher, PolicyRaised


def _rows(*values: float) -> TensorDict:
    return TensorDict(x=torch.tensor(values), batch_size=[len(values)])


class BlockedFirst:
    """Doubles ``x``; its first call blocks until released (so requests pile up behind it);
    refuses negative values."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.calls: list[int] = []

    def __call__(self, td: TensorDict) -> torch.Tensor:
        self.calls.append(td.batch_size[0])
        if len(self.calls) == 1:
            self.release.wait(30)
        if (td["x"] < 0).any():
            raise ValueError("negative x")
        return td["x"] * 2

    def wait_for_first_call(self) -> None:
        deadline = time.monotonic() + 30
        while not self.calls:
            assert time.monotonic() < deadline
            time.sleep(0.01)


def test_waiting_requests_share_a_call_and_a_raising_one_fails_alone() -> None:
    policy = BlockedFirst()
    batcher = Batcher(policy, max_rows=64, max_wait=0.0)
    first = batcher.submit(_rows(1.0))
    policy.wait_for_first_call()
    waiting = [batcher.submit(_rows(v, v)) for v in (1.0, -1.0, 3.0)]
    policy.release.set()
    assert first.result(30).tolist() == [2.0]
    assert waiting[0].result(30).tolist() == [2.0, 2.0]
    assert waiting[2].result(30).tolist() == [6.0, 6.0]
    with pytest.raises(PolicyRaised, match="ValueError: negative x"):
        waiting[1].result(30)
    assert policy.calls == [1, 6, 2, 2, 2]  # the merged call of 6 rows raised; each alone
    batcher.close()


def test_merged_calls_stay_within_max_rows() -> None:
    policy = BlockedFirst()
    batcher = Batcher(policy, max_rows=4, max_wait=0.0)
    batcher.submit(_rows(0.0))
    policy.wait_for_first_call()
    waiting = [batcher.submit(_rows(*[1.0] * rows)) for rows in (3, 1, 2, 5)]
    policy.release.set()
    assert [answer.result(30).shape[0] for answer in waiting] == [3, 1, 2, 5]
    assert policy.calls == [1, 4, 2, 5]  # 3+1, then 2 (5 would exceed), then 5 alone
    assert (batcher.stats.requests, batcher.stats.calls, batcher.stats.rows) == (5, 4, 12)
    batcher.close()
