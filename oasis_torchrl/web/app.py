"""The drive page put together from its settings: world, pilot, recording, replay and server,
running on threads of their own (:class:`RunningPage`), for ``oasis-torchrl play``, tests and
benchmarks alike."""

from __future__ import annotations

import asyncio
import logging
import os
import secrets
import threading

from torchrl.envs import TransformedEnv

from oasis_torchrl.closing import Closing
from oasis_torchrl.config.web import PlayConfig, is_loopback
from oasis_torchrl.drivers import Driver
from oasis_torchrl.protocol import CHUNK
from oasis_torchrl.web.recording import EpisodeRecording, Storage
from oasis_torchrl.web.replay import EpisodeReplay
from oasis_torchrl.web.server import PageServer
from oasis_torchrl.web.session import DriveSession
from oasis_torchrl.web.takeover import Pilot

logger = logging.getLogger(__name__)

TOKEN_VARIABLE = "OASIS_PLAY_TOKEN"
START_TIMEOUT_S = 300.0


def page_token(host: str) -> str | None:
    """The token the page requires: ``OASIS_PLAY_TOKEN`` if set; otherwise none on loopback and
    a random one on any other address.

    Example:
        >>> page_token("127.0.0.1") is None or TOKEN_VARIABLE in os.environ
        True
        >>> len(page_token("0.0.0.0")) >= 16
        True
    """
    token = os.environ.get(TOKEN_VARIABLE) or None
    if token is None and not is_loopback(host):
        token = secrets.token_urlsafe(16)
    return token


def _recording(cfg: PlayConfig) -> EpisodeRecording | None:
    if cfg.root is None:
        return None
    size = None if cfg.image_size is None else (int(cfg.image_size[0]), int(cfg.image_size[1]))
    storage = Storage(
        repo_id=cfg.repo_id,
        fps=cfg.env.server.fps,
        image_size=size,
        vcodec=cfg.vcodec,
        crf=cfg.crf,
    )
    return EpisodeRecording(cfg.root, storage, append=cfg.append)


def _world(cfg: PlayConfig, driver: Driver | None) -> TransformedEnv:
    from oasis_torchrl.envs import make_env

    env = make_env(
        cfg.env,
        all_frames=True,
        frame_stack=None if driver is None else driver.frame_stack,
        expert=driver is not None and driver.needs_expert,
    )
    env.set_seed(cfg.seed)
    return env


class RunningPage(Closing):
    """The page served for ``cfg`` while the context is open (the world opens on entry).

    Attributes:
        url: the page's address, with the token if one is required.
        session: the driven session.

    Example (a test opens ``page.url`` in a browser):
        >>> from oasis_torchrl.config import load_config, to_object
        >>> sizes = ["env.server.width=96", "env.server.height=64"]
        >>> cfg = to_object(load_config("play", ["port=0", *sizes]))
        >>> with RunningPage(cfg) as page:
        ...     page.url.startswith("http://127.0.0.1:")
        True
    """

    def __init__(self, cfg: PlayConfig, *, token: str | None = None) -> None:
        self.cfg = cfg
        self.token = token if token is not None else page_token(cfg.host)
        self.url = ""
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="page", daemon=True)
        driver = None
        if cfg.policy is not None:
            from oasis_torchrl.drivers import load_driver

            driver = load_driver(cfg.policy)
        recording = _recording(cfg)
        self.session = DriveSession(
            lambda: _world(cfg, driver),
            Pilot(driver),
            lambda message: self.server.publish(message),
            recording=recording,
            period=CHUNK / cfg.env.server.fps,
            jpeg_quality=cfg.jpeg_quality,
        )
        replay = (
            None if cfg.root is None else EpisodeReplay(cfg.root, cfg.repo_id, cfg.jpeg_quality)
        )
        self.server = PageServer(self.session, token=self.token, replay=replay)

    def __enter__(self) -> RunningPage:
        self.session.start(START_TIMEOUT_S)
        self._thread.start()
        try:
            started = asyncio.run_coroutine_threadsafe(
                self.server.start(self.cfg.host, self.cfg.port), self._loop
            )
            self.url = started.result(START_TIMEOUT_S)
        except BaseException:
            self.close()
            raise
        logger.info("drive the world model at %s", self.url)
        return self

    def close(self) -> None:
        """Stop serving, drop a running episode (saved ones stay), close the world."""
        if self._thread.is_alive():
            stopped = asyncio.run_coroutine_threadsafe(self.server.stop(), self._loop)
            try:
                stopped.result(30)
            finally:
                self._loop.call_soon_threadsafe(self._loop.stop)
                self._thread.join(30)
        self.session.close()
