"""BoundedWorker: order, back-pressure (bounded memory) and errors reaching the caller."""

from __future__ import annotations

import threading

import pytest

from oasis_torchrl.viz.worker import BoundedWorker


def test_submit_waits_while_max_pending_jobs_are_queued() -> None:
    release, done = threading.Event(), []
    worker = BoundedWorker(max_pending=2)
    worker.submit(release.wait)
    worker.submit(done.append, "queued")
    third = threading.Thread(target=worker.submit, args=(done.append, "third"))
    third.start()
    third.join(timeout=0.5)
    assert third.is_alive()  # both slots are taken: the caller waits instead of queueing
    release.set()
    third.join(timeout=10)
    assert not third.is_alive()
    worker.close()
    assert done == ["queued", "third"]


def test_a_failed_job_is_raised_to_the_caller() -> None:
    worker = BoundedWorker(max_pending=1)

    def fail() -> None:
        raise KeyError("bad record")

    worker.submit(fail)
    with pytest.raises(RuntimeError, match="background writer") as raised:
        worker.drain()
    assert isinstance(raised.value.__cause__, KeyError)
    worker.submit(fail)
    with pytest.raises(RuntimeError):
        worker.close()
    with pytest.raises(ValueError, match="max_pending"):
        BoundedWorker(max_pending=0)
