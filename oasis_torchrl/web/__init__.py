"""Drive the world model in a browser page and record what you drive (``oasis-torchrl play``).

One module per concern: :mod:`~oasis_torchrl.web.messages` (what the page may send),
:mod:`~oasis_torchrl.web.frames` (frames to the page), :mod:`~oasis_torchrl.web.takeover` (who
drives), :mod:`~oasis_torchrl.web.recording` (episodes into a LeRobot dataset),
:mod:`~oasis_torchrl.web.replay` (saved episodes back to the page),
:mod:`~oasis_torchrl.web.session` (the paced driving loop), :mod:`~oasis_torchrl.web.server`
(HTTP and WebSocket), :mod:`~oasis_torchrl.web.app` (all of it from the settings); the page
itself is in ``static/``.
"""

from oasis_torchrl.web.app import RunningPage, page_token
from oasis_torchrl.web.messages import Refused, parse_message

__all__ = ["Refused", "RunningPage", "page_token", "parse_message"]
