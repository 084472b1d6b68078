"""The embedded A2V server of an env with ``endpoint="local"``: what size it renders at and how
many sessions it admits, for the env's rows alone."""

from __future__ import annotations

import math
from dataclasses import replace

from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer, ServerProcess


def render_size(
    server: tuple[int, int], frame_size: tuple[int, int] | None, front_crop: float | None
) -> tuple[int, int]:
    """``(height, width)`` an embedded server renders at: its own size, or, with a front crop,
    at least the size whose centre crop holds ``frame_size`` pixels (rounded up to even), so
    the crop shows detail the cameras' frames lack (:class:`~oasis_torchrl.envs.OasisEnv`
    renders so). Rendering larger is the cheapest correct way: the crop is then cut exactly as
    from the hosted service's 768x512 frames, and the client decodes every camera to
    ``frame_size`` anyway.

    Example:
        >>> render_size((64, 96), (64, 96), 0.25)
        (256, 384)
        >>> render_size((64, 96), (64, 96), None), render_size((512, 768), (64, 96), 0.25)
        ((64, 96), (512, 768))
    """
    if front_crop is None or frame_size is None:
        return server
    needed = (_even(math.ceil(side / front_crop)) for side in frame_size)
    height, width = (max(own, need) for own, need in zip(server, needed, strict=True))
    return height, width


def _even(value: int) -> int:
    return value + value % 2


SPARE_SESSIONS = 4
"""Sessions an env's own server admits beyond its rows: the scene lookups of the top-down view
(one session at a time) and rows re-opened before the server expired their lost sessions."""


def embedded_server(config: ServerConfig, num_envs: int) -> LocalServer | ServerProcess:
    """The embedded server of a local env: a process of its own (its workers at most one per
    row), or, with ``processes=0``, inside the stepping process. Unstarted: the env's pool
    starts it. It serves this env alone, so its session limits admit every row plus
    :data:`SPARE_SESSIONS` whatever ``config`` says.

    Example:
        >>> type(embedded_server(ServerConfig(processes=0), 2)).__name__
        'LocalServer'
        >>> embedded_server(ServerConfig(), 1).config.processes
        1
        >>> embedded_server(ServerConfig(), 32).config.max_sessions_per_key
        36
    """
    sessions = num_envs + SPARE_SESSIONS
    config = replace(
        config,
        max_sessions=max(config.max_sessions, sessions),
        max_sessions_per_key=max(config.max_sessions_per_key, sessions),
    )
    if config.resolved_processes == 0:
        return LocalServer(config)
    return ServerProcess(replace(config, processes=min(config.resolved_processes, num_envs)))
