"""The agent's one rosbridge client (vehicle_agent/rosbridge_client.py): every frame, text or
binary, well formed or not, becomes one typed item, nothing raises; and the connection against a
rosbridge of the test's own: advertise, publish, subscribe, call, the token and its renewal,
reconnection. Against the server's own /rosbridge it is driven by test_robotlink.py and
test_roscamera_rosbridge.py."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator

import cbor2
import pytest

from tests.helpers.stub_rosbridge import StubRosbridge, running
from tests.helpers.waiting import eventually
from vehicle_agent.rosbridge_client import (
    CBOR,
    CallFailed,
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


# -- the connection, against a rosbridge of the test's own ----------------------------------------


@contextlib.asynccontextmanager
async def connected(
    stub: StubRosbridge, token: str | None = None
) -> AsyncIterator[RosbridgeClient]:
    client = RosbridgeClient(stub.url, token)
    await client.connect()
    try:
        yield client
    finally:
        await client.close()


@pytest.fixture
async def stub() -> AsyncIterator[StubRosbridge]:
    async with running(StubRosbridge()) as rosbridge:
        yield rosbridge


async def test_advertise_and_publish_go_out_in_order_after_set_level(stub: StubRosbridge) -> None:
    async with connected(stub) as client:
        client.advertise("/cmd_vel", "geometry_msgs/msg/Twist")
        assert client.publish("/cmd_vel", {"linear": {"x": 1.0}})
        assert client.publish("/cmd_vel", {"linear": {"x": 2.0}})
        await eventually(lambda: len(stub.ops) == 4, 5, "four ops")
    assert [m["op"] for m in stub.ops] == ["set_level", "advertise", "publish", "publish"]
    assert stub.ops[1] | {"id": None} == {
        "op": "advertise",
        "id": None,
        "topic": "/cmd_vel",
        "type": "geometry_msgs/msg/Twist",
    }
    assert [m["msg"]["linear"]["x"] for m in stub.of("publish")] == [1.0, 2.0]


async def test_each_subscription_gets_its_topics_messages_in_json_or_cbor(
    stub: StubRosbridge,
) -> None:
    poses: list[Publication] = []
    images: list[Publication] = []
    async with connected(stub) as client:
        client.subscribe("/pose", "turtlesim/msg/Pose", poses.append)
        client.subscribe(
            "/cam", "sensor_msgs/CompressedImage", images.append, compression=CBOR, queue_length=1
        )
        await eventually(lambda: len(stub.subscribes) == 2, 5, "two subscriptions")
        pose, image = stub.subscribes
        assert (pose["topic"], pose["compression"], "queue_length" in pose) == (
            "/pose",
            "none",
            False,
        )
        assert (image["topic"], image["compression"], image["queue_length"]) == ("/cam", "cbor", 1)
        await stub.publish("/pose", {"x": 1.5}, binary=False)
        await stub.publish("/cam", {"format": "jpeg", "data": JPEG_BYTES})
        await stub.publish("/elsewhere", {"x": 0})
        await eventually(lambda: bool(poses and images), 5, "both messages")
    assert [(p.msg, p.binary) for p in poses] == [({"x": 1.5}, False)]
    assert [(i.msg["data"], i.binary) for i in images] == [(JPEG_BYTES, True)]


async def test_a_status_about_a_subscription_goes_to_it(stub: StubRosbridge) -> None:
    stub.refuse_cbor = True
    statuses: list[StatusOp] = []
    async with connected(stub) as client:
        client.subscribe("/cam", "t", lambda _: None, compression=CBOR, on_status=statuses.append)
        await eventually(lambda: bool(statuses), 5, "the refusal")
    assert (statuses[0].level, statuses[0].msg) == ("warning", "unknown compression cbor")


async def test_any_other_warning_is_said_once(
    stub: StubRosbridge, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="vehicle_agent.rosbridge_client")
    refused = {"op": "status", "level": "warning", "id": "advertise:/x", "msg": "not allowed"}
    marks: list[Publication] = []
    async with connected(stub) as client:
        client.subscribe("/mark", "t", marks.append)
        await eventually(lambda: bool(stub.subscribes), 5, "the subscription")
        for _ in range(3):
            await stub.send(json.dumps(refused))
        await stub.send(json.dumps({**refused, "level": "info", "msg": "fine"}))
        # Frames are read in order: once this one is in, the statuses before it were read.
        await stub.publish("/mark", {}, binary=False)
        await eventually(lambda: bool(marks), 5, "the mark")
    said = [r.message for r in caplog.records if "says" in r.message]
    assert said == [f"rosbridge at {stub.url} says not allowed"]


async def test_a_call_returns_the_services_values_and_fails_clearly_otherwise(
    stub: StubRosbridge,
) -> None:
    stub.services["/add"] = lambda args: ({"sum": args["a"] + args["b"]}, True)
    stub.services["/broken"] = lambda args: ("the turtle is gone", False)
    stub.topic_type = "turtlesim/msg/Pose"
    async with connected(stub) as client:
        assert await client.call("/add", {"a": 2, "b": 3}, 5) == {"sum": 5}
        with pytest.raises(CallFailed, match="/broken failed: the turtle is gone"):
            await client.call("/broken", {}, 5)
        with pytest.raises(CallFailed, match=r"/silent: no answer within 0\.2 s"):
            await client.call("/silent", {}, 0.2)
        assert await client.topic_type("/turtle1/pose") == "turtlesim/msg/Pose"
        stub.topic_type = ""
        assert await client.topic_type("/turtle1/pose") is None
    with pytest.raises(CallFailed, match="not connected"):
        await client.call("/add", {"a": 1, "b": 1}, 5)


async def test_the_token_goes_on_the_handshake_and_a_renewed_one_is_proved_with_auth(
    stub: StubRosbridge,
) -> None:
    async with connected(stub, "first") as client:
        client.renew("second")
        await eventually(lambda: bool(stub.of("auth")), 5, "the auth op")
        assert stub.of("auth") == [{"op": "auth", "token": "second"}]
        # A reconnection shakes hands with the fresh token.
        await stub.drop()
        await eventually(lambda: len(stub.authorizations) == 2, 10, "the reconnection")
    assert stub.authorizations == ["Bearer first", "Bearer second"]


async def test_without_a_token_a_renewal_sends_nothing(stub: StubRosbridge) -> None:
    async with connected(stub) as client:
        client.renew("some-other-servers-token")
        client.advertise("/x", "t")
        await eventually(lambda: bool(stub.of("advertise")), 5, "the advertisement")
    assert stub.authorizations == [None] and not stub.of("auth")


async def test_a_lost_connection_is_opened_again_with_what_it_had(stub: StubRosbridge) -> None:
    poses: list[Publication] = []
    stub.services["/never"] = lambda args: (None, True)
    async with connected(stub) as client:
        client.advertise("/cmd_vel", "geometry_msgs/Twist")
        client.subscribe("/pose", "turtlesim/Pose", poses.append)
        await eventually(lambda: bool(stub.subscribes), 5, "the subscription")
        first = stub.connection
        await stub.drop()
        await eventually(lambda: not client.connected, 5, "the loss")
        # Down: a velocity command is dropped, not kept to arrive late; a call fails at once.
        assert not client.publish("/cmd_vel", {"linear": {"x": 1.0}})
        with pytest.raises(CallFailed, match="not connected"):
            await client.call("/never", {}, 5)
        await eventually(lambda: client.connected and stub.connection is not first, 10, "again")
        await eventually(lambda: len(stub.subscribes) == 2, 5, "the subscription again")
        assert client.opened == 2
        await stub.publish("/pose", {"x": 3.0}, binary=False)
        await eventually(lambda: bool(poses), 5, "a pose on the new connection")
    ops = [m["op"] for m in stub.ops]
    assert ops == ["set_level", "advertise", "subscribe"] * 2
    assert not any(m["op"] == "publish" for m in stub.ops)


async def test_a_call_pending_when_the_connection_drops_fails_at_once(stub: StubRosbridge) -> None:
    async with connected(stub) as client:
        call = asyncio.create_task(client.call("/nobody/answers", {}, 30))
        await eventually(lambda: bool(stub.of("call_service")), 5, "the call")
        await stub.drop()
        with pytest.raises(CallFailed, match="connection to .* lost"):
            await asyncio.wait_for(call, 5)


async def test_after_close_it_stays_closed(stub: StubRosbridge) -> None:
    async with connected(stub) as client:
        pass
    assert not client.connected
    await asyncio.sleep(1.0)  # two backoff delays: no reconnection came
    assert stub.authorizations == [None]
