"""The compatibility module refuses a library release it was not written for, naming both."""

from __future__ import annotations

import importlib.metadata

import pytest

from oasis_torchrl import compat


@pytest.mark.parametrize("package", sorted(compat.SUPPORTED))
def test_the_installed_releases_are_supported(package: str) -> None:
    compat.require(package)


def test_an_unknown_release_is_refused_with_both_versions_named(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(compat.SUPPORTED, "lerobot", ((0, 7), (0, 8)))
    installed = importlib.metadata.version("lerobot")
    message = f"supports lerobot>=0.7,<0.8, found lerobot {installed}"
    with pytest.raises(compat.UnsupportedVersionError, match=message):
        compat.dropped_video_frames(object())  # checked before the dataset is looked at


def test_ray_weight_sync_takes_the_node_address_not_the_hostname(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import os
    import pickle
    import socket

    import ray
    from torchrl.weight_update import _ray as ray_weight_sync

    monkeypatch.setattr(ray.util, "get_node_ip_address", lambda: "127.0.0.1")
    monkeypatch.delenv(compat.GLOO_INTERFACE_VARIABLE, raising=False)
    seen = {}

    def set_up(scheme: object) -> None:  # what TorchRL's set-up resolves and gloo reads
        hostname = ray_weight_sync.socket.gethostname()
        seen["address"] = ray_weight_sync.socket.gethostbyname(hostname)
        seen["interface"] = os.environ.get(compat.GLOO_INTERFACE_VARIABLE)

    scheme_class = ray_weight_sync.RayWeightSyncScheme
    monkeypatch.setattr(scheme_class, "_setup_distributed_connection_sender", set_up)
    monkeypatch.setattr(scheme_class, "_setup_connection_and_weights_on_receiver_impl", set_up)
    scheme = pickle.loads(pickle.dumps(compat.ray_weight_sync_scheme()))  # as actors get it
    for side in (
        scheme._setup_distributed_connection_sender,
        scheme._setup_connection_and_weights_on_receiver_impl,
    ):
        seen.clear()
        side()
        assert seen == {"address": "127.0.0.1", "interface": "lo"}
        assert ray_weight_sync.socket is socket
        assert compat.GLOO_INTERFACE_VARIABLE not in os.environ


def test_episode_tables_skip_the_image_embedding_only_without_images(tmp_path) -> None:
    import datasets
    import numpy as np
    from lerobot.datasets import dataset_writer
    from lerobot.datasets.io_utils import embed_images
    from PIL import Image

    compat.embed_only_image_tables()
    rows = datasets.Features(
        {
            "action": datasets.Sequence(datasets.Value("float32"), length=2),
            "index": datasets.Value("int64"),
        }
    )
    table = datasets.Dataset.from_dict(
        {"action": [[0.5, -0.25], [1.0, 0.0]], "index": [0, 1]}, features=rows
    )
    skipped = dataset_writer.embed_images(table)
    assert skipped is table  # no row-by-row map ran
    assert skipped.with_format("arrow")[:].equals(embed_images(table).with_format("arrow")[:])
    picture = tmp_path / "frame.png"
    Image.fromarray(np.zeros((4, 6, 3), np.uint8)).save(picture)
    images = datasets.Dataset.from_dict(
        {"image": [str(picture)]}, features=datasets.Features({"image": datasets.Image()})
    )
    embedded = dataset_writer.embed_images(images).with_format("arrow")[:]
    assert embedded.column("image")[0]["bytes"].as_py() == picture.read_bytes()
