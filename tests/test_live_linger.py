"""After a run, the live server serves until its viewers have left: a viewer who came and
left during the run ends it at once (no deadline of wall time decides; only events)."""

from __future__ import annotations

import asyncio
import json
import threading

import pytest

websockets = pytest.importorskip("websockets")
pytest.importorskip("foxglove")

from ffexp.live import LiveOptions  # noqa: E402
from ffexp.live.server import LiveServer  # noqa: E402

DEADLINE_S = 60.0


async def _visit(url: str) -> None:
    """Connect, subscribe to the first advertised channel, wait until data or the
    subscription is taken, leave."""
    async with websockets.connect(url, subprotocols=["foxglove.sdk.v1"],
                                  close_timeout=0.5) as ws:
        assert json.loads(await asyncio.wait_for(ws.recv(), DEADLINE_S))["op"] == "serverInfo"
        adv = json.loads(await asyncio.wait_for(ws.recv(), DEADLINE_S))
        channel = adv["channels"][0]["id"]
        await ws.send(json.dumps({"op": "subscribe",
                                  "subscriptions": [{"id": 1, "channelId": channel}]}))


def test_a_viewer_who_left_during_the_run_ends_serving_after_it() -> None:
    server = LiveServer(LiveOptions(host="127.0.0.36", port=0))
    server.start()
    try:
        subscribed = threading.Event()
        original = server._subscribe

        def spy(client_id: int, channel_id: int) -> None:
            original(client_id, channel_id)
            subscribed.set()

        server._subscribe = spy  # type: ignore[method-assign]
        asyncio.run(_visit(server.url))  # the viewer came (during the run) and left
        assert subscribed.wait(DEADLINE_S)
        why: list[str] = []
        done = threading.Thread(target=lambda: why.append(server.linger(lambda: False)))
        done.start()
        done.join(DEADLINE_S)
        assert not done.is_alive(), "still serving after its only viewer left"
        assert why == ["the viewer disconnected"]
    finally:
        server.close()
