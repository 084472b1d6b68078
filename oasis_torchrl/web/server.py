"""The page's HTTP and WebSocket server (aiohttp), one port.

Routes: ``/`` the page, ``/static/<file>`` its assets (all shipped in the package: no CDN, so it
works offline and through an SSH port forward), ``/ws`` the WebSocket that carries frames and
status to the page and the page's messages (:mod:`oasis_torchrl.web.messages`) back.

Safety. With a ``token``, every request (the page, each asset, the socket) must carry it as
``?token=...``, compared in constant time; binding anything but loopback requires one
(:func:`oasis_torchrl.commands.play.run` makes sure). One page drives: the first to send a
driving message holds the session until its socket closes, and every other page's driving
messages are refused as ``second_driver`` while it still watches. A refused message is answered
with ``{"type": "error", "error": <name>, ...}`` and changes nothing. The world's API key stays
in the server's env and never reaches a page.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import logging
from collections.abc import Awaitable, Callable
from importlib import resources
from typing import Any
from urllib.parse import quote

from aiohttp import WSMsgType, web

from oasis_torchrl.web.messages import Control, Record, Refused, Replay, parse_message
from oasis_torchrl.web.session import DriveSession

logger = logging.getLogger(__name__)

STATIC = resources.files("oasis_torchrl.web") / "static"
CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css"}
QUEUE_MESSAGES = 10
"""Messages waiting for one page (two chunks: 4 frames and a status each). A page that falls
behind loses the oldest, so what it shows stays live instead of lagging ever more."""

Replayer = Callable[[int, Callable[[bytes | dict[str, Any]], Awaitable[None]]], Awaitable[None]]


class Page:
    """One connected page: its socket and the messages waiting to be sent to it."""

    def __init__(self, socket: web.WebSocketResponse) -> None:
        self.socket = socket
        self.queue: asyncio.Queue[bytes | dict[str, Any]] = asyncio.Queue(QUEUE_MESSAGES)
        self.dropped = 0

    def offer(self, message: bytes | dict[str, Any]) -> None:
        """Queue a message; a page that is behind loses its oldest one."""
        if self.queue.full():
            self.queue.get_nowait()
            self.dropped += 1
        self.queue.put_nowait(message)

    async def send(self, message: bytes | dict[str, Any]) -> None:
        """Send a message now (replies, replayed frames)."""
        if isinstance(message, bytes):
            await self.socket.send_bytes(message)
        else:
            await self.socket.send_json(message)

    async def pump(self) -> None:
        """Send queued messages until the socket closes."""
        while not self.socket.closed:
            await self.send(await self.queue.get())


class PageServer:
    """Serves the page for one :class:`~oasis_torchrl.web.session.DriveSession`.

    Args:
        session: the driven session (started by :meth:`start`).
        token: required on every request and socket (None: none required).
        replay: streams a saved episode to a page (None: replay is off).

    Example:
        >>> server = PageServer(None, token="s3cret")  # doctest: +SKIP
        >>> url = await server.start("127.0.0.1", 0)  # doctest: +SKIP
    """

    def __init__(
        self, session: DriveSession, *, token: str | None = None, replay: Replayer | None = None
    ) -> None:
        self.session = session
        self.token = token
        self.replay = replay
        self.pages: set[Page] = set()
        self.driver: Page | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self.app = web.Application(middlewares=[self._check_token])
        self.app.add_routes(
            [
                web.get("/", self._index),
                web.get("/static/{name}", self._static),
                web.get("/ws", self._socket),
            ]
        )

    @property
    def query(self) -> str:
        """The query string every URL of the page carries (the token, if any)."""
        return "" if self.token is None else f"?token={quote(self.token)}"

    def publish(self, message: bytes | dict[str, Any]) -> None:
        """Send a message to every page; safe to call from any thread, never blocks."""
        if self.loop is not None and not self.loop.is_closed():
            self.loop.call_soon_threadsafe(self._fan_out, message)

    def _fan_out(self, message: bytes | dict[str, Any]) -> None:
        for page in self.pages:
            page.offer(message)

    async def start(self, host: str, port: int) -> str:
        """Start serving; returns the page's URL (with the token)."""
        self.loop = asyncio.get_running_loop()
        self._runner = web.AppRunner(self.app, access_log=None)
        await self._runner.setup()
        site = web.TCPSite(self._runner, host, port)
        await site.start()
        bound = self._runner.addresses[0]
        return f"http://{host}:{bound[1]}/{self.query}"

    async def stop(self) -> None:
        """Close every socket and stop serving."""
        for page in list(self.pages):
            await page.socket.close()
        if self._runner is not None:
            await self._runner.cleanup()

    # -- requests -------------------------------------------------------------------------

    @web.middleware
    async def _check_token(
        self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
    ) -> web.StreamResponse:
        if self.token is not None and not hmac.compare_digest(
            request.query.get("token", "").encode(), self.token.encode()
        ):
            raise web.HTTPForbidden(
                text="forbidden: open the page with the URL the server logged (?token=...)\n"
            )
        return await handler(request)

    async def _index(self, request: web.Request) -> web.Response:
        page = (STATIC / "index.html").read_text().replace("{{query}}", self.query)
        return web.Response(text=page, content_type="text/html")

    async def _static(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        asset = STATIC / name
        suffix = "." + name.rsplit(".", 1)[-1]
        if "/" in name or suffix not in CONTENT_TYPES or not asset.is_file():
            raise web.HTTPNotFound(text=f"no asset {name!r}\n")
        return web.Response(body=asset.read_bytes(), content_type=CONTENT_TYPES[suffix])

    async def _socket(self, request: web.Request) -> web.WebSocketResponse:
        socket = web.WebSocketResponse(heartbeat=10.0)
        await socket.prepare(request)
        page = Page(socket)
        self.pages.add(page)
        self.session.page_opened()
        pump = asyncio.create_task(page.pump())
        try:
            page.offer(self.session.status())
            async for message in socket:
                if message.type in (WSMsgType.TEXT, WSMsgType.BINARY):
                    await self._handle(page, message.data)
        finally:
            pump.cancel()
            self.pages.discard(page)
            self.session.page_closed()
            if self.driver is page:
                await self._driver_left()
        return socket

    async def _handle(self, page: Page, data: str | bytes) -> None:
        try:
            message = parse_message(data)
            if isinstance(message, Replay):
                if self.replay is None:
                    raise Refused("no_dataset", "nothing to replay: recording is off")
                await self.replay(message.episode, page.send)
                return
            self._claim(page)
            if isinstance(message, Control):
                self.session.pilot.steer(message)
                return
            result = await asyncio.wrap_future(self.session.submit(message))
            await page.send(
                {"type": "done", "request": type(message).__name__.lower(), "result": result}
            )
        except Refused as refused:
            await page.send(refused.as_message())

    def _claim(self, page: Page) -> None:
        if self.driver is None:
            self.driver = page
            logger.info("a page drives the session")
        elif self.driver is not page:
            raise Refused("second_driver", "another page drives this session; this one watches")

    async def _driver_left(self) -> None:
        """The driving page went away: its input drops, a running episode is dropped (every
        saved one is kept), and the next page to drive may."""
        self.driver = None
        self.session.pilot.release()
        recording = self.session.recording
        if recording is not None and recording.recording:
            with contextlib.suppress(Refused):  # the episode may have ended on its own meanwhile
                await asyncio.wrap_future(self.session.submit(Record("discard")))
        logger.info("the driving page left")
