"""The agent's own rosbridge client (vehicle_agent/rosbridge_client.py): every frame, text or
binary, well formed or not, becomes one typed item; nothing raises."""

from __future__ import annotations

import json

import cbor2
import pytest

from vehicle_agent.rosbridge_client import (
    Ignored,
    Publication,
    RosbridgeClient,
    RosbridgeError,
    ServiceResponseOp,
    StatusOp,
    Unreadable,
    read_frame,
)

JPEG_BYTES = b"\xff\xd8\xff\xe0" + bytes(range(256)) * 4

PUBLISH = {"op": "publish", "topic": "/cam", "msg": {"format": "jpeg", "data": JPEG_BYTES}}


def test_a_cbor_publication_keeps_its_data_as_bytes() -> None:
    item = read_frame(cbor2.dumps(PUBLISH), 12.5, 1000.0)
    assert item == Publication("/cam", {"format": "jpeg", "data": JPEG_BYTES}, True, 12.5, 1000.0)


def test_a_json_publication_is_read_from_a_text_frame() -> None:
    text = json.dumps({"op": "publish", "topic": "/cam", "msg": {"format": "jpeg", "data": "AA=="}})
    item = read_frame(text, 1.0, 2.0)
    assert item == Publication("/cam", {"format": "jpeg", "data": "AA=="}, False, 1.0, 2.0)


def test_status_and_service_responses_are_typed() -> None:
    status = read_frame(
        json.dumps({"op": "status", "level": "warning", "msg": "x", "id": "a"}), 0, 0
    )
    assert status == StatusOp(op="status", level="warning", msg="x", id="a")
    answer = read_frame(
        cbor2.dumps({"op": "service_response", "id": "call:1", "values": {"type": "t"}}), 0, 0
    )
    assert isinstance(answer, ServiceResponseOp)
    assert (answer.id, answer.values, answer.result) == ("call:1", {"type": "t"}, True)


@pytest.mark.parametrize(
    ("frame", "says"),
    [
        (b"\x9f\x01", "not CBOR"),  # an indefinite array never closed
        (b"\xff", "not CBOR"),
        (b"", "not CBOR"),
        (cbor2.dumps([1, 2]), "must be an object"),
        ("[1, 2]", "must be an object"),
        ("{not json", "JSON"),
        ('{"op": 5}', "no string 'op'"),
        (cbor2.dumps({"op": "publish", "msg": {}}), "field 'topic'"),
        (cbor2.dumps({"op": "publish", "topic": "/cam", "msg": b"xx"}), "field 'msg'"),
        ('{"op": "status", "level": 3}', "field 'level'"),
    ],
)
def test_a_frame_that_is_no_message_is_unreadable_and_says_why(
    frame: str | bytes, says: str
) -> None:
    item = read_frame(frame, 0.0, 0.0)
    assert isinstance(item, Unreadable)
    assert says in item.reason
    assert item.binary == isinstance(frame, bytes)


def test_ops_the_client_has_no_use_for_are_ignored() -> None:
    assert read_frame('{"op": "png", "data": "x"}', 0, 0) == Ignored("png")


def test_a_url_that_is_no_websocket_is_refused_at_once() -> None:
    with pytest.raises(RosbridgeError, match="must start with ws:// or wss://"):
        RosbridgeClient("http://robot:9090")


async def test_a_closed_port_is_one_clear_error() -> None:
    client = RosbridgeClient("ws://127.0.0.1:9")
    with pytest.raises(RosbridgeError, match="cannot connect to rosbridge at ws://127.0.0.1:9"):
        await client.connect()
