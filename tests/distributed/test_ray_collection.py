"""Ray collection on a local loopback Ray runtime: two workers, each on its own embedded server.

A lost worker stopping the run (``on_failure="stop"``) is checked through ``record_on_ray`` in
``test_ray_record.py``: one run serves both layers."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn

ray = pytest.importorskip("ray")

from oasis_torchrl.config import EmbeddedServerConfig, EnvConfig  # noqa: E402
from oasis_torchrl.distributed import (  # noqa: E402
    RayCollection,
    RayCollectionConfig,
    env_factory,
    merge_shards,
)

from ._settings import smoke_ppo  # noqa: E402

# The module's shared run is set up in whichever test first needs it: past 300 s on a loaded
# 2-core machine.
pytestmark = [pytest.mark.usefixtures("ray_runtime"), pytest.mark.timeout(600)]

WORKERS, SESSIONS, STEPS = 2, 2, 2
FRAMES_PER_BATCH = WORKERS * SESSIONS * STEPS
HEIGHT, WIDTH = 48, 64
SERVER = EmbeddedServerConfig(width=WIDTH, height=HEIGHT)


def constant_policy(value: float) -> TensorDictModule:
    """A policy whose every action is ``tanh(value)``: the weights decide the action."""
    net = nn.Sequential(nn.Linear(2, 8), nn.Tanh(), nn.Unflatten(-1, (4, 2)))
    set_constant(net, value)
    return TensorDictModule(net, in_keys=["state"], out_keys=["action"])


def set_constant(net: nn.Module, value: float) -> None:
    with torch.no_grad():
        net[0].weight.zero_()
        net[0].bias.fill_(value)


def make_collection(tmp_path: Path | None = None, **overrides) -> tuple[RayCollection, nn.Module]:
    config = RayCollectionConfig(
        num_collectors=WORKERS,
        sessions_per_env=SESSIONS,
        shard_root=None if tmp_path is None else str(tmp_path / "shards"),
        **overrides,
    )
    create_env = env_factory(EnvConfig(max_steps=STEPS, image_size=None, server=SERVER), config)
    policy = constant_policy(0.0)
    collection = RayCollection(
        config,
        create_env,
        policy,
        frames_per_batch=FRAMES_PER_BATCH,
        total_frames=4 * FRAMES_PER_BATCH,
        auto_register_policy_transforms=False,
    )
    return collection, policy


@dataclass
class Run:
    """What one recorded two-worker run left: batches, the collection, the merged dataset."""

    batches: list[TensorDictBase]
    collection: RayCollection
    merged: Path


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    """Two workers, one shard part per batch: a batch, new weights, a batch, worker 1 killed,
    a batch from worker 0 alone; then the shards are merged."""
    root = tmp_path_factory.mktemp("ray")
    collection, policy = make_collection(root, on_failure="continue", part_batches=1)
    with collection:
        batches = iter(collection)
        collected = [next(batches)]
        set_constant(policy.module, 0.5)
        collection.update_policy_weights_(policy)
        collected.append(next(batches))
        ray.kill(collection.collector.remote_collectors[1])
        collected.append(next(batches))
    return Run(collected, collection, merge_shards(root / "shards", root / "merged"))


def test_batches_have_the_expected_shapes(run: Run) -> None:
    first = run.batches[0]
    assert first.batch_size == torch.Size([WORKERS, SESSIONS, STEPS])
    frames = first["next", "pixels", "front"]
    assert frames.shape == (WORKERS, SESSIONS, STEPS, 4, HEIGHT, WIDTH, 3)
    assert frames.dtype == torch.uint8 and frames.float().std() > 0
    assert first["action"].shape == (WORKERS, SESSIONS, STEPS, 4, 2)


def test_weights_reach_the_workers(run: Run) -> None:
    assert torch.allclose(run.batches[0]["action"], torch.zeros(()))
    assert torch.allclose(run.batches[1]["action"], torch.tanh(torch.tensor(0.5)))


def test_a_killed_worker_is_dropped_and_the_other_carries_on(run: Run) -> None:
    assert run.collection.lost_workers == [1]
    assert run.collection.live_workers == [0]
    assert run.batches[2].batch_size == torch.Size([1, SESSIONS, STEPS])


def test_shards_merge_into_one_dataset_keeping_the_lost_workers_parts(run: Run) -> None:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    # max_steps == STEPS: every batch ends one episode per row. Worker 0 recorded 4 batches (the
    # round in which worker 1 died is not yielded but is recorded); worker 1 finalized 2 parts.
    episodes = (4 + 2) * SESSIONS
    assert run.collection.shard_episodes == {0: 4 * SESSIONS}
    dataset = LeRobotDataset("local/merged", root=run.merged, video_backend="pyav")
    assert dataset.meta.total_episodes == episodes
    episode_index = torch.as_tensor(dataset.hf_dataset["episode_index"])
    assert sorted(episode_index.unique().tolist()) == list(range(episodes))
    assert len(dataset) == episodes * STEPS * 4  # one row per frame
    assert dataset[len(dataset) - 1]["observation.images.front"].shape == (3, HEIGHT, WIDTH)


def test_ppo_trains_on_ray_workers(tmp_path: Path) -> None:
    from oasis_torchrl.config import load_config
    from oasis_torchrl.models.checkpoint import load_checkpoint
    from oasis_torchrl.train.ppo import PPOTrainer

    cfg = load_config("ppo", smoke_ppo(tmp_path))
    result = PPOTrainer(cfg).run()
    state = load_checkpoint(result.checkpoint)
    # two batches of 16 env steps, each gathered from both Ray workers, each followed by an update
    assert (state["iteration"], state["frames"]) == (2, 32)
