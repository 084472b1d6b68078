"""Shard parts appear under their names only once finalized; a merge takes exactly those."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from oasis_torchrl.atomic import partial_path
from oasis_torchrl.distributed import ShardRecorder, complete_shards
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig


def test_a_part_is_listed_once_finalized_and_never_while_open(tmp_path: Path) -> None:
    env = OasisEnv(
        "local", 1, all_frames=True, max_steps=2, server=ServerConfig(width=64, height=48)
    )
    shards = ShardRecorder(tmp_path, worker=3, part_batches=2)
    try:
        shards(env.rollout(2, break_when_any_done=False))
        # one batch of two: the part is open, written under its partial name only
        assert partial_path(tmp_path / "worker-003-part-0000").is_dir()
        assert complete_shards(tmp_path) == []
        shards(env.rollout(2, break_when_any_done=False))
    finally:
        env.close()
    assert complete_shards(tmp_path) == [tmp_path / "worker-003-part-0000"]
    assert shards.close() == 2
    assert sorted(path.name for path in tmp_path.iterdir()) == ["worker-003-part-0000"]


def test_unfinished_parts_are_skipped_by_name_and_scratch_ignored(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    # what a worker killed mid-part leaves: its part's partial and its recorder's scratch
    finished, lost = tmp_path / "worker-000-part-0000", tmp_path / "worker-001-part-0001"
    finished.mkdir()
    partial_path(lost).mkdir()
    (tmp_path / f".{partial_path(lost).name}-spill-x1y2").mkdir()
    with caplog.at_level(logging.WARNING):
        assert complete_shards(tmp_path) == [finished]
    assert ".worker-001-part-0001.partial" in caplog.text
    assert "spill" not in caplog.text
