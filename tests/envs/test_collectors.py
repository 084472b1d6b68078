"""OasisEnv inside TorchRL collectors (single and multi-process)."""

from __future__ import annotations

import functools

import grpc
import torch
from tensordict import TensorDict
from torchrl.collectors import Collector, MultiSyncCollector

from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.proto import a2v_pb2, a2v_pb2_grpc
from oasis_torchrl.sim.config import ServerConfig

SMALL = ServerConfig(width=64, height=48)


# a partial of the class pickles by reference, so spawned workers can rebuild it
make_env = functools.partial(
    OasisEnv, "local", num_envs=2, prompts="highway", server=SMALL, max_steps=3
)


def test_collector_yields_batches_with_resets() -> None:
    collector = Collector(make_env, policy=None, frames_per_batch=8, total_frames=16)
    try:
        batches = list(collector)
    finally:
        collector.shutdown()
    assert len(batches) == 2
    batch = batches[0]
    assert batch.batch_size == (2, 4)
    assert batch["next", "pixels", "front"].dtype == torch.uint8
    # max_steps=3: the third step of every row is truncated and the row starts over
    assert batch["next", "truncated"][:, 2].all()


def test_two_worker_multiprocess_collector() -> None:
    collector = MultiSyncCollector(
        [make_env, make_env],
        policy=None,
        frames_per_batch=8,
        total_frames=16,
    )
    try:
        shapes = [tuple(batch["next", "pixels", "front"].shape[-3:]) for batch in collector]
    finally:
        collector.shutdown()
    assert shapes == [(48, 64, 3)] * 2


def _forget_on_the_server(env: OasisEnv, row: int) -> None:
    """Finish ``row``'s session behind the env's back: the server no longer knows it, as after
    an idle expiry (without waiting for one)."""
    state = env.pool._runtime.sessions[row].state
    with grpc.insecure_channel(env.pool._target) as channel:
        response = a2v_pb2_grpc.A2VServiceStub(channel).Finish(
            a2v_pb2.FinishRequest(session_id=state.info.session_id),
            metadata=state.metadata,
            timeout=30,
        )
    assert not response.HasField("error"), response.error


def test_lost_session_is_reopened_for_its_row_only() -> None:
    env = OasisEnv("local", num_envs=2, server=SMALL, max_steps=50)
    try:
        env.reset()
        action = TensorDict(action=torch.full((2, 4, 2), 0.0), batch_size=[2])
        env.step(action)
        _forget_on_the_server(env, row=1)
        out = env.step(action)["next"]
        assert out["truncated"].flatten().tolist() == [False, True]
        assert out["info", "session_restarts"].flatten().tolist() == [0, 1]
        assert out["pixels", "front"][1].float().mean() > 0
    finally:
        env.close()
