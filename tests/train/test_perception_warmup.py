"""The perception warm-up: the encoder fitted to the first env steps' privileged state."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import torch

from oasis_torchrl.config import load_config
from oasis_torchrl.models.checkpoint import load_checkpoint, net_from_checkpoint
from oasis_torchrl.train.perception_warmup import PerceptionWarmup
from oasis_torchrl.train.ppo import PPOTrainer

from .conftest import tiny_ppo
from .test_aux_replay import _batch, _loss


def _csv(path: Path) -> list[tuple[float, float]]:
    with path.open() as handle:
        return [(float(row[0]), float(row[1])) for row in csv.reader(handle)]


def test_the_warmup_fits_the_encoder_and_the_auxiliary_head_alone() -> None:
    loss = _loss()
    net = loss.net
    untouched = {
        name: value.clone()
        for name, value in net.state_dict().items()
        if not name.startswith(("encoder.", "aux."))
    }
    encoder = net.encoder.project_weight.detach().clone()
    warmup = PerceptionWarmup(loss, capacity=64, mini_batch_size=16, lr=1e-3)
    warmup.extend(_batch(64))
    losses = warmup.fit(steps=80, progress=False)
    assert len(losses) == 80 and len(warmup) == 64
    assert sum(losses[-10:]) < 0.25 * sum(losses[:10])
    assert not torch.equal(net.encoder.project_weight, encoder)
    for name, value in net.state_dict().items():
        if name in untouched:  # actor, critic and action scale wait for PPO
            torch.testing.assert_close(value, untouched[name], msg=name)


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError, match=r"warmup\.frames trains the auxiliary loss: set loss"):
        load_config("ppo", ["warmup.frames=1024", "loss.aux_coeff=0"])
    with pytest.raises(ValueError, match=r"warmup\.frames \(20480\) must leave PPO some of"):
        load_config("ppo", ["warmup.frames=20480", "collector.total_frames=20480"])
    with pytest.raises(ValueError, match=r"warmup\.frames \(32\) must hold at least one"):
        load_config("ppo", ["warmup.frames=32"])
    with pytest.raises(ValueError, match=r"warmup\.lr must be a number > 0\.0, got 0\.0"):
        load_config("ppo", ["warmup.frames=1024", "warmup.lr=0"])


def test_ppo_starts_after_the_warmup_whose_env_steps_count(tmp_path: Path) -> None:
    overrides = tiny_ppo(
        tmp_path,
        48,
        "eval.every=0",
        "warmup.frames=32",
        "warmup.steps=40",
        "warmup.mini_batch_size=8",
    )
    trainer = PPOTrainer(load_config("ppo", overrides))
    fresh = {key: value.clone() for key, value in trainer.net.state_dict().items()}
    trainer.run()

    scalars = tmp_path / "logs" / "ppo" / "scalars"
    (first,) = _csv(scalars / "warmup" / "aux_loss_first.csv")
    (last,) = _csv(scalars / "warmup" / "aux_loss_last.csv")
    assert first[0] == last[0] == 32  # logged once the warm-up's 32 env steps were driven
    assert last[1] < first[1]
    assert [frames for frames, _ in _csv(scalars / "optim" / "updates.csv")] == [48]
    state = load_checkpoint(tmp_path / "checkpoints" / "latest.pt")
    assert (state["iteration"], state["frames"]) == (1, 48)  # one PPO update, 32 + 16 env steps
    assert not torch.equal(net_from_checkpoint(state).aux[0].weight, fresh["aux.0.weight"])

    resumed = PPOTrainer(load_config("ppo", [*overrides, "resume=latest"]))
    resumed.run()  # past the warm-up: it is not driven again
    assert _csv(scalars / "warmup" / "aux_loss_first.csv") == [first]


def test_a_named_driver_drives_the_warmup(tmp_path: Path) -> None:
    overrides = tiny_ppo(
        tmp_path,
        48,
        "eval.every=0",
        "warmup.frames=32",
        "warmup.steps=2",
        "warmup.mini_batch_size=8",
        "warmup.driver=constant:throttle=1.0,steering=0.0",
        "aux_replay.capacity=48",
        "aux_replay.mini_batch_size=8",
    )
    trainer = PPOTrainer(load_config("ppo", overrides))
    trainer.run()
    previous = trainer.update.aux_replay.buffer.storage[:]["state"]  # the previous chunk's action
    warmup, ppo = previous[:32], previous[32:]
    driven = warmup[warmup.abs().sum(-1) > 0]  # an episode's first row has none
    assert len(driven) >= 16 and torch.equal(driven, torch.tensor([1.0, 0.0]).expand_as(driven))
    assert not torch.equal(ppo[ppo.abs().sum(-1) > 0][:1], torch.tensor([[1.0, 0.0]]))

    expert = load_config("ppo", [*overrides[:-2], "warmup.driver=autopilot"])
    with pytest.raises(ValueError, match=r"warmup\.driver='autopilot' drives with the embedded"):
        PPOTrainer(expert).run()
