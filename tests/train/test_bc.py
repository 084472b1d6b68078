"""Behaviour cloning on a tiny autopilot dataset: updates, the LeRobot folder, the data cache."""

from __future__ import annotations

import shutil
from pathlib import Path

import av
import pytest
import torch
from lerobot_policy_oasis import OasisConfig, OasisPolicy
from lerobot_policy_oasis.processor_oasis import ResizeFramesProcessorStep
from torch.utils.data import DataLoader, default_collate

from oasis_torchrl.config import load_config
from oasis_torchrl.data.video_frames import MissingFrameError
from oasis_torchrl.drivers.folders import load_net
from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS
from oasis_torchrl.train.bc import PARTIAL_POLICY, TRAINING_STATE, BCTrainer, open_dataset
from oasis_torchrl.train.bc_data import InMemoryBCDataset


def _bc_config(dataset: Path, output: Path, *extra: str):
    return load_config(
        "bc",
        [
            f"dataset.root={dataset}",
            f"output_dir={output}",
            "policy.image_size=[32,48]",
            "train.steps=4",
            "train.batch_size=8",
            "train.log_every=1",
            "eval.episodes=0",
            "progress=false",
            *extra,
        ],
    )


def test_a_video_short_of_its_rows_is_named_by_episode_and_camera(
    tiny_dataset: Path, tmp_path: Path
) -> None:
    """The cache decodes each video file once; a file that lost its last frames (here re-encoded
    without them) fails naming the episode and the camera whose rows have no frame."""
    root = shutil.copytree(tiny_dataset, tmp_path / "short")
    video = next((root / "videos" / "observation.images.front").rglob("*.mp4"))
    with av.open(str(video)) as source:
        frames = [frame.to_ndarray(format="rgb24") for frame in source.decode(video=0)]
    with av.open(str(video), "w") as target:
        stream = target.add_stream("h264", rate=20)
        stream.height, stream.width = frames[0].shape[:2]
        for image in frames[:-3]:
            target.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        target.mux(stream.encode())
    dataset = open_dataset(_bc_config(root, tmp_path / "run").dataset, OasisConfig(device="cpu"))
    with pytest.raises(MissingFrameError, match=r"episode 1 of observation\.images\.front: .*mp4"):
        InMemoryBCDataset(dataset, progress=False)


def test_bc_steps_train_the_actor_and_save_a_lerobot_policy(
    tiny_dataset: Path, tmp_path: Path
) -> None:
    trainer = BCTrainer(_bc_config(tiny_dataset, tmp_path))
    before = {key: value.clone() for key, value in trainer.policy.model.state_dict().items()}
    result = trainer.run()

    assert torch.isfinite(torch.tensor(result.final_loss))
    after = result.policy.model.state_dict()
    assert not torch.equal(before["encoder.convs.0.weight"], after["encoder.convs.0.weight"])
    assert not torch.equal(before["actor.2.weight"], after["actor.2.weight"])
    torch.testing.assert_close(before["critic.2.weight"], after["critic.2.weight"])

    batch = trainer.preprocessor(next(iter(trainer.loader)))
    loaded = OasisPolicy.from_pretrained(result.policy_dir)
    torch.testing.assert_close(
        loaded.predict_action_chunk(batch), result.policy.eval().predict_action_chunk(batch)
    )
    net = load_net(result.policy_dir)
    torch.testing.assert_close(net.state_dict()["actor.2.bias"], after["actor.2.bias"])


def test_the_auxiliary_loss_trains_the_auxiliary_head(tiny_dataset: Path, tmp_path: Path) -> None:
    trainer = BCTrainer(_bc_config(tiny_dataset, tmp_path, "policy.aux_weight=1.0"))
    before = trainer.policy.model.aux[0].weight.clone()
    result = trainer.run()
    assert not torch.equal(before, result.policy.model.aux[0].weight)
    logged = (tmp_path / "logs" / "bc" / "scalars" / "bc" / "aux_loss.csv").read_text().split()
    assert len(logged) == 4 and all(float(line.split(",")[1]) > 0 for line in logged)
    net = load_net(result.policy_dir)  # a policy folder with its auxiliary head still loads
    assert net.config.aux_outputs == len(PRIVILEGED_FIELDS)


def test_a_warm_start_goes_on_with_the_auxiliary_head(tiny_dataset: Path, tmp_path: Path) -> None:
    first = BCTrainer(_bc_config(tiny_dataset, tmp_path / "a", "policy.aux_weight=1.0")).run()
    again = BCTrainer(
        _bc_config(
            tiny_dataset, tmp_path / "b", "policy.aux_weight=1.0", f"init_from={first.policy_dir}"
        )
    )
    trained = first.policy.model.state_dict()
    for key, value in again.policy.model.state_dict().items():
        torch.testing.assert_close(value, trained[key], msg=key)


def test_in_memory_samples_and_batches_match_lerobot_samples(
    tiny_dataset: Path, tmp_path: Path
) -> None:
    dataset = open_dataset(_bc_config(tiny_dataset, tmp_path).dataset, OasisConfig(device="cpu"))
    cached = InMemoryBCDataset(dataset, progress=False)
    assert len(cached) == len(dataset) == 32
    for index in (0, 13, 15, 31):  # 15 and 31 end an episode: padded actions
        expected, actual = dataset[index], cached[index]
        assert set(actual) == set(expected) - {
            "task",
            "task_index",
            "next.reward",
            "next.done",
            "episode_seed",
        }
        for key in actual:
            tolerance = {"atol": 1 / 255, "rtol": 0} if key in cached.camera_keys else {}
            torch.testing.assert_close(actual[key], expected[key], msg=key, **tolerance)
    batch = next(
        iter(DataLoader(cached, batch_size=4, sampler=[0, 13, 15, 31], collate_fn=cached.collate))
    )
    expected = default_collate([{key: dataset[i][key] for key in batch} for i in (0, 13, 15, 31)])
    for key, value in batch.items():
        tolerance = {"atol": 1 / 255, "rtol": 0} if key in cached.camera_keys else {}
        torch.testing.assert_close(value, expected[key], msg=key, **tolerance)
    assert cached[15]["action_is_pad"].tolist() == [False, True, True, True]
    assert cached[16]["observation.state_is_pad"].tolist() == [True, False]  # episode start
    assert cached[16]["observation.images.front"].shape == (2, 3, 32, 48)


def test_a_negative_shift_is_refused() -> None:
    with pytest.raises(ValueError, match=r"train\.shift_pad must be an integer >= 0, got -1"):
        load_config("bc", ["train.shift_pad=-1"])


def test_the_cache_keeps_frames_at_the_policys_size(tiny_dataset: Path, tmp_path: Path) -> None:
    dataset = open_dataset(_bc_config(tiny_dataset, tmp_path).dataset, OasisConfig(device="cpu"))
    cached = InMemoryBCDataset(dataset, image_size=(16, 24), progress=False)
    resize = ResizeFramesProcessorStep(size=(16, 24))
    for index in (0, 17):
        expected = resize.observation(dataset[index])
        for key in cached.camera_keys:
            assert cached[index][key].shape == (2, 3, 16, 24)
            torch.testing.assert_close(cached[index][key], expected[key], atol=2 / 255, rtol=0)


def test_the_cache_shifts_the_frames_as_bytes(tiny_dataset: Path, tmp_path: Path) -> None:
    cfg = _bc_config(tiny_dataset, tmp_path, "train.shift_pad=2")
    dataset = open_dataset(cfg.dataset, OasisConfig(device="cpu"))
    seen: list[torch.dtype] = []

    def invert(frames: torch.Tensor) -> torch.Tensor:
        seen.append(frames.dtype)
        return 255 - frames

    plain = InMemoryBCDataset(dataset, progress=False)
    inverted = InMemoryBCDataset(dataset, progress=False, frame_transform=invert)
    for key in plain.camera_keys:
        torch.testing.assert_close(inverted[3][key], 1 - plain[3][key])
    assert set(seen) == {torch.uint8}
    # The trainer hands its random shifts to the cache instead of shifting floats per batch.
    trainer = BCTrainer(cfg)
    assert trainer.shift_in_loop is None
    assert trainer.loader.dataset.frame_transform.keywords == {"pad": 2}


def test_only_a_finished_run_writes_the_policy_folder(
    tiny_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The policy so far goes to checkpoints/last; policy/ is written once, at the end, so the
    main job never reuses the folder of a run stopped half way."""
    saved: list[Path] = []
    save = BCTrainer.save
    monkeypatch.setattr(
        BCTrainer, "save", lambda self, path: saved.append(path) or save(self, path)
    )
    BCTrainer(_bc_config(tiny_dataset, tmp_path, "train.save_every=2")).run()
    assert saved == [tmp_path / PARTIAL_POLICY, tmp_path / "policy"]
    assert OasisPolicy.from_pretrained(tmp_path / PARTIAL_POLICY) is not None


def test_a_run_stopped_half_way_resumes_where_it_stopped(
    tiny_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A stop after step 3 of 4 leaves step 2's state; ``resume=latest`` takes steps 3 and 4
    only, from step 2's weights and optimizer, on the batches a run never stopped takes, and
    writes policy/: the weights of that run, to the bit."""
    steps: list[int] = []
    forward = OasisPolicy.forward

    def counted(self, batch, reduction="mean"):
        steps.append(len(steps) + 1)
        if len(steps) == 3 and not resumed:
            raise KeyboardInterrupt  # a stop half way through
        return forward(self, batch, reduction)

    resumed = False
    monkeypatch.setattr(OasisPolicy, "forward", counted)
    with pytest.raises(KeyboardInterrupt):
        BCTrainer(_bc_config(tiny_dataset, tmp_path, "train.save_every=2")).run()
    assert not (tmp_path / "policy").exists()
    state = torch.load(tmp_path / PARTIAL_POLICY / TRAINING_STATE, weights_only=False)
    assert state["step"] == 2
    resumed, steps[:] = True, []
    trainer = BCTrainer(_bc_config(tiny_dataset, tmp_path, "train.save_every=2", "resume=latest"))
    saved = trainer.optimizer.state_dict()["state"]
    assert all(int(each["step"]) == 2 for each in saved.values())  # Adam's, after 2 steps
    for name, value in trainer.policy.state_dict().items():
        torch.testing.assert_close(value, state["policy"][name])
    trainer.run()
    assert steps == [1, 2]  # the run's steps 3 and 4
    assert (tmp_path / "policy" / "model.safetensors").exists()
    never_stopped = BCTrainer(
        _bc_config(tiny_dataset, tmp_path / "never_stopped", "train.save_every=2")
    )
    never_stopped.run()
    for name, value in never_stopped.policy.state_dict().items():
        assert torch.equal(value, trainer.policy.state_dict()[name]), name
    fresh = _bc_config(tiny_dataset, tmp_path / "fresh", "resume=latest")
    with pytest.raises(FileNotFoundError, match=r"nothing to resume: .*training_state\.pt"):
        BCTrainer(fresh)
    elsewhere = _bc_config(
        tiny_dataset, tmp_path / "elsewhere", f"resume={tmp_path}/{PARTIAL_POLICY}"
    )
    assert BCTrainer(elsewhere).done_steps == 2  # a saved state named by its folder
