"""``oasis-torchrl train ppo`` when a Ray collector worker dies: one line naming it and what to
do, not a traceback (the collection raising :class:`WorkerLostError` on a killed worker is
``test_ray_collection.py``'s)."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

pytest.importorskip("ray")

from oasis_torchrl.cli import main
from oasis_torchrl.distributed import WorkerLostError


def test_a_lost_worker_is_one_line_naming_it_and_what_to_do(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    capsys: pytest.CaptureFixture[str],
) -> None:
    def lose_a_worker(cfg: object) -> None:
        raise WorkerLostError("Ray collector worker(s) [1] lost (on_failure='stop')")

    monkeypatch.setattr("oasis_torchrl.train.ppo.train_ppo", lose_a_worker)
    with caplog.at_level(logging.ERROR):
        assert main(["train", "ppo", f"output_dir={tmp_path}"]) == 1
    errors = [record.getMessage() for record in caplog.records if record.levelno >= logging.ERROR]
    assert len(errors) == 1 and "\n" not in errors[0]
    assert "worker(s) [1] lost" in errors[0] and "resume=latest" in errors[0]
    assert "Traceback" not in capsys.readouterr().err


def test_other_runtime_errors_still_raise(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def fail(cfg: object) -> None:
        raise RuntimeError("a bug")

    monkeypatch.setattr("oasis_torchrl.train.ppo.train_ppo", fail)
    with pytest.raises(RuntimeError, match="a bug"):
        main(["train", "ppo", f"output_dir={tmp_path}"])
