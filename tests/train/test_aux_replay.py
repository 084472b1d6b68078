"""The auxiliary replay: a ring of past observations that trains the encoder to see."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.config import load_config
from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
from oasis_torchrl.train.aux_replay import AuxiliaryReplay
from oasis_torchrl.train.ppo import PPOTrainer
from oasis_torchrl.train.ppo_loss import DrivingPPOLoss

from .conftest import tiny_ppo

FIELDS = 10


def _loss(aux_coeff: float = 1.0) -> DrivingPPOLoss:
    torch.manual_seed(0)
    net = DrivingNet(DrivingNetConfig(image_size=(32, 48), aux_outputs=FIELDS))
    return DrivingPPOLoss(make_actor_critic(net), aux_coeff=aux_coeff)


def _batch(rows: int, first: int = 0) -> TensorDict:
    """Rows whose privileged state is a function of their frames' brightness."""
    brightness = torch.arange(first, first + rows) % 8 * 30
    frames = brightness.view(rows, 1, 1, 1, 1).expand(rows, 2, 32, 48, 3).to(torch.uint8)
    truth = (brightness.float() / 210.0).view(rows, 1).expand(rows, FIELDS)
    return TensorDict(
        {
            "frame_stack": {c: frames for c in ("left_forward", "front", "right_forward")},
            "state": torch.zeros(rows, 2),
            "critic_inputs": truth.clone(),
            "action": torch.zeros(rows, 4, 2),  # a batch's other keys are not kept
        },
        [rows],
    )


def test_the_ring_keeps_the_newest_rows_and_only_what_the_loss_reads() -> None:
    replay = AuxiliaryReplay(_loss(), capacity=24, mini_batch_size=8)
    replay.extend(_batch(16))
    replay.extend(_batch(16, first=100))
    assert len(replay) == 24
    stored = replay.buffer.storage[:]
    assert "action" not in stored.keys()
    assert stored["frame_stack", "front"].dtype == torch.uint8  # frames stay bytes
    # the 8 oldest rows were overwritten by the newest batch's last ones
    assert int(stored["critic_inputs"][:, 0].mul(210).round().eq(30 * (100 % 8)).sum()) >= 1


def test_replayed_steps_teach_the_auxiliary_head() -> None:
    loss = _loss()
    replay = AuxiliaryReplay(loss, capacity=64, mini_batch_size=16)
    replay.extend(_batch(64))
    probe = loss.features(_batch(64).clone())
    before = loss.aux_loss(probe).item()
    optimizer = torch.optim.Adam(loss.parameters(), lr=1e-3)
    for _ in range(60):
        optimizer.zero_grad(set_to_none=True)
        replay.loss().backward()
        optimizer.step()
    after = loss.aux_loss(loss.features(_batch(64).clone())).item()
    assert after < 0.25 * before
    assert loss.net.actor[0].weight.grad is None  # the actor is not the replay's to train


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match=r"set loss\.aux_coeff > 0"):
        AuxiliaryReplay(_loss(aux_coeff=0.0), capacity=64, mini_batch_size=8)
    with pytest.raises(ValueError, match="at least one minibatch"):
        AuxiliaryReplay(_loss(), capacity=4, mini_batch_size=8)
    with pytest.raises(RuntimeError, match="empty"):
        AuxiliaryReplay(_loss(), capacity=8, mini_batch_size=8).loss()
    with pytest.raises(ValueError, match=r"set loss\.aux_coeff > 0 too"):
        load_config("ppo", ["aux_replay.capacity=1024", "loss.aux_coeff=0"])
    with pytest.raises(ValueError, match=r"aux_replay\.capacity \(64\) must hold at least one"):
        load_config("ppo", ["aux_replay.capacity=64"])
    with pytest.raises(ValueError, match=r"aux_replay\.steps must be an integer >= 0, got -1"):
        load_config("ppo", ["aux_replay.steps=-1"])


def test_ppo_replays_every_batch_it_collected(tmp_path: Path) -> None:
    overrides = tiny_ppo(
        tmp_path,
        48,
        "eval.every=0",
        "aux_replay.capacity=40",
        "aux_replay.steps=3",
        "aux_replay.mini_batch_size=8",
    )
    PPOTrainer(load_config("ppo", overrides)).run()
    scalars = tmp_path / "logs" / "ppo" / "scalars"
    with (scalars / "optim" / "aux_replay_rows.csv").open() as handle:
        rows = [float(row[1]) for row in csv.reader(handle)]
    assert rows == [16.0, 32.0, 40.0]  # every batch went in, up to the capacity
    with (scalars / "loss" / "aux_replay.csv").open() as handle:
        losses = [float(row[1]) for row in csv.reader(handle)]
    assert len(losses) == 3 and all(value > 0 for value in losses)
