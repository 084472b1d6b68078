"""Talking to the page's WebSocket as the page does, from a test."""

from __future__ import annotations

import json
from typing import Any

import aiohttp


async def next_json(
    socket: aiohttp.ClientWebSocketResponse, timeout: float = 120
) -> dict[str, Any]:
    """The next JSON message (frame messages, which are binary, are skipped)."""
    while True:
        message = await socket.receive(timeout=timeout)
        if message.type == aiohttp.WSMsgType.TEXT:
            return json.loads(message.data)
        assert message.type == aiohttp.WSMsgType.BINARY, message
