"""LeRobot's choice of a video backend logs at most one line once ``oasis_torchrl`` is imported
(where torchcodec cannot load FFmpeg, LeRobot would otherwise log a traceback per FFmpeg
version), and the project's readers choose PyAV before LeRobot tries."""

from __future__ import annotations

import importlib.util
import logging

import pytest

import oasis_torchrl  # noqa: F401  (installs the filter)
from oasis_torchrl.data.loading import default_video_backend
from oasis_torchrl.video_fallback import ONE_LINE

pytest.importorskip("lerobot", reason="the lerobot extra is not installed")


def test_lerobots_default_backend_choice_logs_one_line(caplog: pytest.LogCaptureFixture) -> None:
    from lerobot.utils.import_utils import get_safe_default_video_backend

    with caplog.at_level(logging.WARNING):
        backend = get_safe_default_video_backend()
    messages = [record.getMessage() for record in caplog.records]
    assert all("\n" not in message for message in messages), messages
    if backend == "pyav" and importlib.util.find_spec("torchcodec"):  # installed, cannot load
        assert ONE_LINE in messages
    assert default_video_backend() == backend  # the project picks what LeRobot ends with
