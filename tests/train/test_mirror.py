"""Mirror augmentation on batches of a real recorded dataset, and in the BC trainer."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.config import load_config
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, PRIVILEGED_KEY
from oasis_torchrl.train.bc import BCTrainer
from oasis_torchrl.train.mirror import Mirror

LEFT, FRONT, RIGHT = (f"observation.images.{c}" for c in ("left_forward", "front", "right_forward"))
STEERING = ("action", "observation.state")


def _trainer(dataset: Path, output: Path, *extra: str) -> BCTrainer:
    return BCTrainer(
        load_config(
            "bc",
            [
                f"dataset.root={dataset}",
                f"output_dir={output}",
                "policy.image_size=[32,48]",
                "policy.aux_weight=1.0",
                "train.steps=3",
                "train.batch_size=32",
                "eval.episodes=0",
                "progress=false",
                *extra,
            ],
        )
    )


@pytest.fixture
def batch(tiny_dataset: Path, tmp_path: Path) -> dict:
    """All 32 rows of the tiny autopilot dataset as one raw batch."""
    return next(iter(_trainer(tiny_dataset, tmp_path).loader))


def test_a_reflection_flips_and_swaps_cameras_and_mirrors_steering_and_sides(batch: dict) -> None:
    out = Mirror([LEFT, FRONT, RIGHT], PRIVILEGED_FIELDS, share=1.0, steering_keys=STEERING)(batch)

    torch.testing.assert_close(out[FRONT], batch[FRONT].flip(-1))
    torch.testing.assert_close(out[LEFT], batch[RIGHT].flip(-1))
    torch.testing.assert_close(out[RIGHT], batch[LEFT].flip(-1))
    for key in ("action", "observation.state"):
        torch.testing.assert_close(out[key][..., 0], batch[key][..., 0])
        torch.testing.assert_close(out[key][..., 1], -batch[key][..., 1])
    field = {name: i for i, name in enumerate(PRIVILEGED_FIELDS)}
    state, mirrored = batch[PRIVILEGED_KEY], out[PRIVILEGED_KEY]
    assert state[:, field["lanes_left"]].ne(state[:, field["lanes_right"]]).any()  # not trivial
    torch.testing.assert_close(mirrored[:, field["lanes_left"]], state[:, field["lanes_right"]])
    torch.testing.assert_close(
        mirrored[:, field["lane_obstacle_distance_right"]],
        state[:, field["lane_obstacle_distance_left"]],
    )
    for name in ("lane_offset", "heading_error", "lateral_offset"):
        torch.testing.assert_close(mirrored[:, field[name]], -state[:, field[name]])
    for name in ("speed", "obstacle_distance", "lane_obstacle_distance"):
        torch.testing.assert_close(mirrored[:, field[name]], state[:, field[name]])


def test_reflecting_twice_gives_the_batch_back_and_share_picks_samples(batch: dict) -> None:
    keys = [LEFT, FRONT, RIGHT]
    always = Mirror(keys, PRIVILEGED_FIELDS, share=1.0, steering_keys=STEERING)
    twice = always(always(batch))
    for key in (*keys, "action", "observation.state", PRIVILEGED_KEY):
        torch.testing.assert_close(twice[key], batch[key], msg=key)

    half = Mirror(
        keys,
        PRIVILEGED_FIELDS,
        share=0.5,
        generator=torch.Generator().manual_seed(0),
        steering_keys=STEERING,
    )
    out = half(batch)
    reflected = out[FRONT].ne(batch[FRONT]).flatten(1).any(-1)
    assert 0 < int(reflected.sum()) < len(reflected)
    steering = batch["action"][..., 1]
    torch.testing.assert_close(out["action"][reflected, :, 1], -steering[reflected])
    torch.testing.assert_close(out["action"][~reflected], batch["action"][~reflected])
    torch.testing.assert_close(out[LEFT][~reflected], batch[LEFT][~reflected])
    assert Mirror(keys, None, share=0.0)(batch)[FRONT] is batch[FRONT]


def test_what_cannot_be_mirrored_is_named() -> None:
    with pytest.raises(ValueError, match=r"observation\.images\.top"):
        Mirror([FRONT, "observation.images.top"], None)
    with pytest.raises(ValueError, match="right_forward"):
        Mirror([LEFT, FRONT], None)
    with pytest.raises(ValueError, match="obstacle_distance_left"):
        Mirror([FRONT], ["speed", "obstacle_distance_left"])
    with pytest.raises(ValueError, match=r"train.mirror .* got 1.5"):
        load_config("bc", ["dataset.root=drives", "train.mirror=1.5"])


def test_the_trainer_mirrors_when_asked(tiny_dataset: Path, tmp_path: Path) -> None:
    assert _trainer(tiny_dataset, tmp_path / "off").mirror is None
    trainer = _trainer(tiny_dataset, tmp_path / "on", "train.mirror=0.5")
    assert trainer.mirror is not None and trainer.mirror.share == 0.5
    result = trainer.run()
    assert torch.isfinite(torch.tensor(result.final_loss))


def test_a_ppo_tensordict_is_reflected_in_its_own_layout() -> None:
    cameras = ("left_forward", "front", "right_forward")
    frames = torch.randint(0, 255, (3, 4, 2, 6, 8, 3), dtype=torch.uint8)  # camera, B, depth...
    state = torch.rand(4, len(PRIVILEGED_FIELDS))
    batch = TensorDict(
        {
            "frame_stack": {camera: frames[i] for i, camera in enumerate(cameras)},
            "state": torch.tensor([[0.7, 0.2]]).expand(4, 2).clone(),
            "critic_inputs": state,
        },
        [4],
    )
    mirror = Mirror(
        [("frame_stack", camera) for camera in cameras],
        PRIVILEGED_FIELDS,
        share=1.0,
        steering_keys=["state"],
        privileged_key="critic_inputs",
        width_dim=-2,
    )
    out = mirror(batch)
    # channels-last frames flip along their width, not their colour
    torch.testing.assert_close(out["frame_stack", "left_forward"], frames[2].flip(-2))
    torch.testing.assert_close(out["frame_stack", "front"], frames[1].flip(-2))
    assert out["state"][:, 1].eq(-0.2).all() and out["state"][:, 0].eq(0.7).all()
    field = {name: i for i, name in enumerate(PRIVILEGED_FIELDS)}
    torch.testing.assert_close(out["critic_inputs"][:, field["lanes_left"]], state[:, 5])
    torch.testing.assert_close(out["critic_inputs"][:, field["lane_offset"]], -state[:, 3])
    assert torch.equal(batch["frame_stack", "front"], frames[1])  # the input is left alone
    twice = mirror(out)
    for key in batch.keys(include_nested=True, leaves_only=True):
        torch.testing.assert_close(twice[key], batch[key], msg=str(key))
