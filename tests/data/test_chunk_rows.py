"""The chunk-to-row mapping on hand-built env steps that follow the env specs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from oasis_torchrl.data.chunk_rows import batch_to_rows, infer_layout
from oasis_torchrl.data.features import build_features, check_columns

from ._fake_env import CAMERAS, FakeEnvRun, action, frame, reward


def test_frame_rows_follow_the_documented_table() -> None:
    batch = FakeEnvRun([[3]]).batch(3)
    layout = infer_layout(batch)
    assert layout.cameras == CAMERAS and layout.actions_per_row == 1
    rows = batch_to_rows(batch, layout)
    check_columns(rows.columns, build_features(layout), leading=3)
    t = 1  # a middle step: the state of row 4t comes from the previous chunk
    images = rows.columns["observation.images.front"][0, t]
    for j in range(4):
        np.testing.assert_array_equal(images[j], frame(0, 0, 4 * t + 3 + j, 1))
    state, act = rows.columns["observation.state"][0, t], rows.columns["action"][0, t]
    np.testing.assert_array_equal(state[0], action(0, 0, t - 1, 3))
    np.testing.assert_array_equal(state[1:], [action(0, 0, t, k) for k in range(3)])
    np.testing.assert_array_equal(act, [action(0, 0, t, k) for k in range(4)])
    np.testing.assert_array_equal(
        rows.columns["next.reward"][0, t, :, 0], [0, 0, 0, reward(0, 0, t)]
    )
    assert rows.columns["next.done"][0, :, :, 0].tolist() == [[False] * 4] * 2 + [
        [False] * 3 + [True]
    ]
    assert rows.done.tolist() == [[False, False, True]]
    assert rows.columns["observation.state"][0, 0, 0].tolist() == [0.0, 0.0]  # after reset


def test_chunk_rows_hold_the_last_frame_and_the_whole_chunk() -> None:
    batch = FakeEnvRun([[2]], all_frames=False).batch(2)
    layout = infer_layout(batch)
    assert layout.actions_per_row == 4
    rows = batch_to_rows(batch, layout)
    np.testing.assert_array_equal(
        rows.columns["observation.images.left_forward"][0, 1, 0], frame(0, 0, 7, 0)
    )
    np.testing.assert_array_equal(
        rows.columns["action"][0, 1, 0], np.stack([action(0, 0, 1, k) for k in range(4)]).ravel()
    )
    np.testing.assert_array_equal(rows.columns["observation.state"][0, 1, 0], action(0, 0, 0, 3))
    assert rows.columns["next.reward"][0, :, 0, 0].tolist() == [reward(0, 0, 0), reward(0, 0, 1)]


def test_repeated_actions_spread_over_frame_rows() -> None:
    batch = FakeEnvRun([[2]]).batch(2)
    batch["action"] = batch["action"][:, :, 0]  # an env with chunk_actions=False
    rows = batch_to_rows(batch, infer_layout(batch))
    assert (rows.columns["action"][0, 0] == action(0, 0, 0, 0)).all()


def test_reduced_resolution_and_env_rows_kept_apart() -> None:
    batch = FakeEnvRun([[1, 1], [2]]).batch(2)
    layout = infer_layout(batch, image_size=(24, 32))
    rows = batch_to_rows(batch, layout)
    assert rows.columns["observation.images.front"].shape == (2, 2, 4, 24, 32, 3)
    assert rows.tasks == [["road 0-0", "road 0-1"], ["road 1-0", "road 1-0"]]
    assert rows.seeds.tolist() == [[0, 1], [1000, 1000]]


def test_bad_inputs_name_the_key() -> None:
    batch = FakeEnvRun([[2]]).batch(2)
    layout = infer_layout(batch)
    features = build_features(layout)
    rows = batch_to_rows(batch, layout)
    rows.columns["observation.state"] = rows.columns["observation.state"].astype(np.float64)
    with pytest.raises(TypeError, match=r"observation.state: expected float32 .* got float64"):
        check_columns(rows.columns, features, leading=3)
    wrong = batch.clone()
    wrong["pixels", "front"] = wrong["pixels", "front"].float()
    with pytest.raises(TypeError, match=r"\('pixels', 'front'\) must be uint8, got torch.float32"):
        batch_to_rows(wrong, layout)
    del batch["next", "reward"]
    with pytest.raises(KeyError, match="reward"):
        batch_to_rows(batch, layout)
    batch = FakeEnvRun([[2]]).batch(2)
    batch["action"] = torch.zeros(1, 2, 3, 2)
    with pytest.raises(ValueError, match=r"'action' must be \[1, 2, 4, 2\]"):
        batch_to_rows(batch, layout)
