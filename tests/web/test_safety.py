"""The page refuses what it must, by name, without disturbing the session: requests and sockets
without the token, malformed or out-of-range messages, a second driver."""

from __future__ import annotations

import asyncio
import json
from urllib.error import HTTPError
from urllib.request import urlopen

import aiohttp
import pytest

from oasis_torchrl.web import RunningPage

from ._socket import next_json

TOKEN = "s3cret-token"


def _base(page: RunningPage) -> str:
    return page.url.split("?")[0]


def test_the_token_is_required_on_every_request_and_socket(serve_page) -> None:
    page = serve_page(token=TOKEN)
    assert page.url.endswith(f"/?token={TOKEN}")
    base = _base(page)
    for path in ("", "static/drive.js", "static/drive.css", "ws"):
        with pytest.raises(HTTPError) as refused:
            urlopen(f"{base}{path}", timeout=30)
        assert refused.value.code == 403
        with pytest.raises(HTTPError):
            urlopen(f"{base}{path}?token=wrong", timeout=30)
    with urlopen(page.url, timeout=30) as index:
        html = index.read().decode()
    assert f"static/drive.js?token={TOKEN}" in html  # the page's assets carry the token
    with urlopen(f"{base}static/drive.js?token={TOKEN}", timeout=30) as script:
        assert b"oasisPage" in script.read()

    async def sockets() -> None:
        async with aiohttp.ClientSession() as client:
            with pytest.raises(aiohttp.WSServerHandshakeError):
                await client.ws_connect(f"{base}ws")
            async with client.ws_connect(f"{base}ws?token={TOKEN}") as socket:
                assert (await next_json(socket))["type"] == "status"

    asyncio.run(sockets())


async def _reply(socket: aiohttp.ClientWebSocketResponse, text: str) -> dict:
    """Send ``text``; the next JSON reply that is not a status (frames and statuses skipped)."""
    await socket.send_str(text)
    while (reply := await next_json(socket))["type"] == "status":
        pass
    return reply


async def _chunks(page: RunningPage, count: int) -> None:
    """Wait until the session drove ``count`` more chunks."""
    start = page.session.chunks
    while page.session.chunks < start + count:
        await asyncio.sleep(0.05)


def test_bad_messages_and_a_second_driver_are_refused_by_name(serve_page) -> None:
    page = serve_page()
    url = _base(page) + "ws"

    async def drive() -> None:
        async with aiohttp.ClientSession() as client:
            driver = await client.ws_connect(url)
            watcher = await client.ws_connect(url)
            control = {"type": "control", "throttle": 0.5, "steering": -0.25, "seq": 1}
            await driver.send_json(control)
            refusals = {
                "not json": "malformed_message",
                "[1, 2]": "malformed_message",
                '{"type": "control", "throttle": "fast", "steering": 0, "seq": 2}': (
                    "malformed_message"
                ),
                '{"type": "control", "throttle": 1.5, "steering": 0, "seq": 2}': (
                    "action_out_of_range"
                ),
                '{"type": "control", "throttle": NaN, "steering": 0, "seq": 2}': (
                    "action_not_finite"
                ),
                '{"type": "control", "throttle": 0, "steering": Infinity, "seq": 2}': (
                    "action_not_finite"
                ),
                '{"type": "fly"}': "unknown_type",
                '{"type": "record", "command": "start"}': "no_dataset",
                '{"type": "takeover", "human": true}': "no_policy",
                "x" * 5000: "malformed_message",
            }
            for text, name in refusals.items():
                assert (await _reply(driver, text))["error"] == name, text
            second = json.dumps({**control, "throttle": -1.0, "seq": 9})
            assert (await _reply(watcher, second))["error"] == "second_driver"
            # The session drives on with the first page's input.
            assert page.session.pilot.seq == 1
            await _chunks(page, 2)
            assert page.session.last["action"][0, 0].tolist() == [0.5, -0.25]
            # Once the driver leaves, its input drops and another page may drive.
            await driver.close()
            while page.server.driver is not None:
                await asyncio.sleep(0.05)
            await _chunks(page, 2)
            assert page.session.last["action"][0, 0].tolist() == [0.0, 0.0]
            await watcher.send_str(second)
            while page.session.pilot.seq != 9:
                await asyncio.sleep(0.05)
            await watcher.close()

    asyncio.run(drive())
