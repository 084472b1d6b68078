"""LeRobot's fallback from torchcodec to PyAV in one log line, not pages of FFmpeg errors.

LeRobot decodes videos with torchcodec whenever the package is installed; where FFmpeg's shared
libraries are missing (``make ffmpeg-libs`` installs them) it falls back to PyAV, logging
torchcodec's whole loading error, one traceback per FFmpeg version tried, each time it picks a
default. :func:`shorten_video_fallback` rewrites that warning to one line. Importing
``oasis_torchrl`` installs it, so LeRobot's tools (which import the project's plugins before
parsing their flags) and any process that imports the package log the fallback as one line; the
project's own readers pick PyAV before LeRobot tries
(:func:`oasis_torchrl.data.loading.default_video_backend`).
"""

from __future__ import annotations

import logging

LEROBOT_LOGGER = "lerobot.utils.import_utils"
"""The logger of LeRobot's choice of a default video backend."""

ONE_LINE = (
    "torchcodec cannot load FFmpeg's shared libraries (Debian's ffmpeg package; `sudo make "
    "ffmpeg-libs` in a checkout): LeRobot decodes videos with PyAV"
)


class OneLineFallback(logging.Filter):
    """Turn LeRobot's torchcodec-to-PyAV warning into :data:`ONE_LINE`; pass other records.

    Example:
        >>> record = logging.LogRecord("lerobot", logging.WARNING, "", 0, "%s", ("page",), None)
        >>> record.msg = "Could not load libtorchcodec...\\n...Falling back to 'pyav' as a default"
        >>> OneLineFallback().filter(record), record.getMessage() == ONE_LINE
        (True, True)
    """

    def filter(self, record: logging.LogRecord) -> bool:
        message = str(record.msg)
        if "torchcodec" in message and "pyav" in message and "\n" in message:
            record.msg, record.args = ONE_LINE, ()
        return True


def shorten_video_fallback() -> None:
    """Install :class:`OneLineFallback` on LeRobot's logger (once).

    Example:
        >>> shorten_video_fallback()
        >>> sum(isinstance(f, OneLineFallback) for f in logging.getLogger(LEROBOT_LOGGER).filters)
        1
    """
    lerobot_logger = logging.getLogger(LEROBOT_LOGGER)
    if not any(isinstance(known, OneLineFallback) for known in lerobot_logger.filters):
        lerobot_logger.addFilter(OneLineFallback())
