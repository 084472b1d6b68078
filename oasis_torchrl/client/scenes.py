"""Scene layouts by prompt and seed, asked of a server through the protocol.

The embedded server's worlds are deterministic: a prompt and a seed name one scene. A
:class:`SceneSource` looks one up the way any client can: it opens a session of its own,
prompts it with that prompt and seed, asks ``SimService/GetScene`` and finishes the session.
Answers are kept (least recently used first out), so an episode's scene is asked once however
many times it is drawn. Servers without ``SimService`` (the hosted model) have no scenes: the
source says so once and answers None from then on.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Callable

from oasis_torchrl.client.channel import TlsSetting
from oasis_torchrl.client.errors import DecartRoboticsError, UnsupportedFeatureError
from oasis_torchrl.client.pool import SessionPool
from oasis_torchrl.client.sync_client import A2VClient
from oasis_torchrl.proto import sim_pb2

logger = logging.getLogger(__name__)

SceneLookup = Callable[[str, int], "sim_pb2.SceneResponse | None"]
"""``lookup(prompt, seed)``: the static world of an episode, or None when it is not known."""


class SceneSource:
    """``source(prompt, seed)``: the ``SceneResponse`` a server answers for that world.

    Args:
        endpoint: the server's A2V endpoint, or a :class:`SessionPool` whose endpoint and key
            are read at each lookup (a pool that runs its own embedded server knows them only
            once it has started).
        api_key: the key of a URL endpoint (default: ``DECART_API_KEY``).
        tls: force TLS on or off (default: from the endpoint's scheme).
        timeout: per-call deadline, seconds.
        cache_size: scenes kept.

    Example:
        >>> from oasis_torchrl.sim.launcher import LocalServer
        >>> with LocalServer(width=64, height=48) as server:
        ...     scenes = SceneSource(server.endpoint, server.api_key)
        ...     scene = scenes("rural road", 3)
        ...     scene.seed, len(scene.centerline_x) > 100, scene.ego_length > 0
        (3, True, True)
    """

    def __init__(
        self,
        endpoint: str | SessionPool,
        api_key: str | None = None,
        *,
        tls: TlsSetting = None,
        timeout: float = 30.0,
        cache_size: int = 64,
    ) -> None:
        if cache_size < 1:
            raise ValueError(f"cache_size must be >= 1, got {cache_size}")
        self.endpoint = endpoint
        self.api_key = api_key
        self.tls = tls
        self.timeout = timeout
        self.cache_size = cache_size
        self._scenes: OrderedDict[tuple[str, int], sim_pb2.SceneResponse] = OrderedDict()
        self._unsupported = False
        self._lock = threading.Lock()

    def __call__(self, prompt: str, seed: int) -> sim_pb2.SceneResponse | None:
        """The scene of ``prompt`` and ``seed``; None when the server has no scenes."""
        key = (prompt, int(seed))
        with self._lock:
            if self._unsupported:
                return None
            if key in self._scenes:
                self._scenes.move_to_end(key)
                return self._scenes[key]
            try:
                scene = self._ask(*key)
            except UnsupportedFeatureError as error:
                logger.warning("no scene layouts from this server: %s", error)
                self._unsupported = True
                return None
            self._scenes[key] = scene
            if len(self._scenes) > self.cache_size:
                self._scenes.popitem(last=False)
            return scene

    def _ask(self, prompt: str, seed: int) -> sim_pb2.SceneResponse:
        endpoint, api_key, tls = self._address()
        with A2VClient(
            endpoint, api_key=api_key, tls=tls, timeout=self.timeout, required_streams=()
        ) as client:
            client.prompt(prompt, seed=seed)
            return client.scene()

    def _address(self) -> tuple[str, str | None, TlsSetting]:
        if not isinstance(self.endpoint, SessionPool):
            return self.endpoint, self.api_key, self.tls
        pool = self.endpoint
        if pool.endpoint is None:
            raise DecartRoboticsError(
                "the session pool has not started: the endpoint of its server is not known yet"
            )
        return pool.endpoint, pool.api_key, pool.tls
