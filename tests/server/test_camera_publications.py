"""Malformed camera publications on the server's ``/rosbridge`` get the ``status`` error
docs/camera.md promises -- with no ``set_level`` first, as a publisher that knows nothing of
statuses sends them -- and go nowhere."""

from __future__ import annotations

import asyncio
import json

import pytest
from websockets.asyncio.client import connect

from app.server.serve import RunningServer
from tests.helpers.sockets import recv, rosbridge_url

TOPIC = "/camera/image_raw"
GOOD = {"height": 1, "width": 1, "encoding": "rgb8", "step": 3, "data": "AAAA"}


@pytest.mark.parametrize(
    ("bad", "field"),
    [({"height": -1}, "height"), ({"data": "!!! not base64"}, "base64")],
    ids=["negative height", "data not base64"],
)
async def test_a_malformed_image_is_refused_with_a_status_error(
    server: RunningServer, bad: dict[str, object], field: str
) -> None:
    url = rosbridge_url(server)
    async with connect(url) as publisher, connect(url) as watcher:
        advertise = {"op": "advertise", "topic": TOPIC, "type": "sensor_msgs/msg/Image"}
        await publisher.send(json.dumps(advertise))
        await watcher.send(json.dumps({"op": "subscribe", "topic": TOPIC}))
        publish = {"op": "publish", "id": "p1", "topic": TOPIC, "msg": GOOD | bad}
        await publisher.send(json.dumps(publish))
        reply = await recv(publisher)
        assert (reply["op"], reply["level"], reply["id"]) == ("status", "error", "p1")
        assert TOPIC in reply["msg"] and field in reply["msg"]
        # The watcher gets the next good image and never the bad one.
        await publisher.send(json.dumps(publish | {"id": "p2", "msg": GOOD}))
        received = await recv(watcher)
        assert received["op"] == "publish" and received["msg"]["height"] == 1
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(publisher.recv(), 0.3)  # the good one is not answered
