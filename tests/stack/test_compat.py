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
