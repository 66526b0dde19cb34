"""Camera topics on the sans-I/O rosbridge (app/rosbridge/): a client advertises and publishes
images, the others subscribe in JSON or CBOR; bad images are refused naming the field."""

from __future__ import annotations

import base64
import json
import logging
import math
from typing import Any

import cbor2
import pytest

from app.protocol.ros import RosFlavour
from app.rosbridge.protocol import RosbridgeSession, encode
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import TurtleSim

TOPIC = "/camera/image/compressed"
JPEG = b"\xff\xd8\xff\xe0" + bytes(range(256)) * 8
IMAGE = {
    "header": {"stamp": {"sec": 1_700_000_000, "nanosec": 250}, "frame_id": "camera"},
    "format": "jpeg",
    "data": base64.b64encode(JPEG).decode(),
}


def hub(flavour: RosFlavour = "2") -> RosbridgeHub:
    return RosbridgeHub(TurtleSim(), flavour)


def session(hub: RosbridgeHub) -> RosbridgeSession:
    opened = hub.open_session()
    assert send(opened, op="set_level", level="warning") == []
    return opened


def send(session: RosbridgeSession, **message: Any) -> list[dict[str, Any]]:
    return session.receive(json.dumps(message))


def camera(publisher: RosbridgeSession, kind: str = "sensor_msgs/msg/CompressedImage") -> None:
    assert send(publisher, op="advertise", topic=TOPIC, type=kind) == []


def frames(subscriber: RosbridgeSession) -> list[str | bytes]:
    return subscriber.take_frames()


def test_a_published_image_reaches_a_json_subscriber_with_its_data_in_base64() -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    camera(publisher)
    assert send(watcher, op="subscribe", topic=TOPIC, type="sensor_msgs/CompressedImage") == []
    assert send(publisher, op="publish", topic=TOPIC, msg=IMAGE) == []
    (frame,) = frames(watcher)
    assert isinstance(frame, str)
    message = json.loads(frame)
    assert (message["op"], message["topic"]) == ("publish", TOPIC)
    assert base64.b64decode(message["msg"]["data"]) == JPEG
    assert message["msg"]["header"] == IMAGE["header"]
    assert frames(watcher) == []  # only what is new


def test_a_cbor_subscription_gets_binary_frames_with_the_data_as_bytes() -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    camera(publisher)
    assert send(watcher, op="subscribe", topic=TOPIC, compression="cbor") == []
    assert send(publisher, op="publish", topic=TOPIC, msg=IMAGE) == []
    (frame,) = frames(watcher)
    assert isinstance(frame, bytes)
    message = cbor2.loads(frame)
    assert message["msg"]["data"] == JPEG
    assert message["msg"]["format"] == "jpeg"
    # The same image in JSON is a third larger: base64.
    json_size = len(encode({"op": "publish", "topic": TOPIC, "msg": message["msg"]}, False) or "")
    assert len(frame) < json_size < len(frame) * 1.4


def test_poses_come_in_cbor_too_when_asked() -> None:
    server = hub()
    watcher = session(server)
    assert send(watcher, op="subscribe", topic="/turtle1/pose", compression="cbor") == []
    server.tick(1.0)
    (frame,) = frames(watcher)
    assert isinstance(frame, bytes)
    assert set(cbor2.loads(frame)["msg"]) >= {"x", "y", "theta"}


def test_one_id_asking_for_cbor_makes_the_topics_stream_cbor() -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    camera(publisher)
    send(watcher, op="subscribe", topic=TOPIC, id="a")
    send(watcher, op="subscribe", topic=TOPIC, id="b", compression="cbor")
    send(publisher, op="publish", topic=TOPIC, msg=IMAGE)
    (frame,) = frames(watcher)
    assert isinstance(frame, bytes)
    send(watcher, op="unsubscribe", topic=TOPIC, id="b")
    send(publisher, op="publish", topic=TOPIC, msg=IMAGE)
    (frame,) = frames(watcher)
    assert isinstance(frame, str)


def test_compressions_other_than_none_and_cbor_are_refused() -> None:
    server = hub()
    watcher = session(server)
    (status,) = send(watcher, op="subscribe", topic="/turtle1/pose", compression="png", id="s")
    assert status["level"] == "error" and status["id"] == "s"
    assert "compression" in status["msg"] and "'cbor'" in status["msg"]


def test_a_camera_topic_keeps_only_its_latest_image() -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    camera(publisher)
    send(watcher, op="subscribe", topic=TOPIC, queue_length=10)
    for n in range(3):
        send(publisher, op="publish", topic=TOPIC, msg={**IMAGE, "format": f"jpeg{n}"})
    (frame,) = frames(watcher)
    assert isinstance(frame, str) and json.loads(frame)["msg"]["format"] == "jpeg2"


@pytest.mark.parametrize(
    ("flavour", "header"),
    [
        ("1", {"seq": 0, "stamp": {"secs": 1_700_000_000, "nsecs": 250}, "frame_id": "camera"}),
        ("jazzy", {"stamp": {"sec": 1_700_000_000, "nanosec": 250}, "frame_id": "camera"}),
    ],
)
def test_images_are_sent_in_the_hubs_flavour(flavour: RosFlavour, header: dict[str, Any]) -> None:
    server = hub(flavour)
    publisher, watcher = session(server), session(server)
    kind = "sensor_msgs/CompressedImage" if flavour == "1" else "sensor_msgs/msg/CompressedImage"
    camera(publisher, kind)
    send(watcher, op="subscribe", topic=TOPIC)
    send(publisher, op="publish", topic=TOPIC, msg=IMAGE)  # a ROS 2 stamp, whatever the hub
    (frame,) = frames(watcher)
    assert json.loads(frame)["msg"]["header"] == header


def test_a_raw_image_is_relayed_field_for_field() -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    camera(publisher, "sensor_msgs/msg/Image")
    send(watcher, op="subscribe", topic=TOPIC, compression="cbor")
    image = {"height": 2, "width": 3, "encoding": "yuv422", "step": 6, "data": list(range(12))}
    # The server checks the message's shape, as rosbridge does; an encoding the agent will not
    # read goes through.
    assert send(publisher, op="publish", topic=TOPIC, msg=image) == []
    (frame,) = frames(watcher)
    msg = cbor2.loads(frame)["msg"]
    assert msg["data"] == bytes(range(12))
    assert (msg["height"], msg["width"], msg["encoding"], msg["step"]) == (2, 3, "yuv422", 6)
    assert msg["is_bigendian"] == 0 and msg["header"]["frame_id"] == ""


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"data": "not base64!"}, "data"),
        ({"data": [1, 300]}, "data"),
        ({"format": 5}, "format"),
        ({"width": 3}, "width"),
        ({"header": {"stamp": {"sec": "now"}}}, "header.stamp.sec"),
    ],
)
def test_an_image_of_the_wrong_shape_is_refused_naming_the_field(
    change: dict[str, Any], field: str
) -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    camera(publisher)
    send(watcher, op="subscribe", topic=TOPIC)
    (status,) = send(publisher, op="publish", topic=TOPIC, msg={**IMAGE, **change}, id="p")
    assert status["level"] == "error" and status["id"] == "p"
    assert f"not a sensor_msgs/CompressedImage: field '{field}'" in status["msg"]
    assert frames(watcher) == []


def test_publishing_on_a_topic_nobody_declared_is_refused() -> None:
    server = hub()
    publisher = session(server)
    (status,) = send(publisher, op="publish", topic="/camera/x", msg=IMAGE)
    assert "unknown topic '/camera/x'" in status["msg"]


def test_a_topic_keeps_the_type_it_was_declared_with() -> None:
    server = hub()
    publisher, other = session(server), session(server)
    camera(publisher)
    (status,) = send(other, op="advertise", topic=TOPIC, type="sensor_msgs/Image")
    assert f"{TOPIC} has type sensor_msgs/msg/CompressedImage" in status["msg"]
    (status,) = send(other, op="subscribe", topic="/chatter", type="std_msgs/String")
    assert "unknown topic '/chatter'" in status["msg"]


def test_a_subscription_may_come_before_the_publisher() -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    assert send(watcher, op="subscribe", topic=TOPIC, type="sensor_msgs/CompressedImage") == []
    assert send(publisher, op="publish", topic=TOPIC, msg=IMAGE) == []  # declared by the subscribe
    assert len(frames(watcher)) == 1


def topic_type(client: RosbridgeSession, topic: str) -> str:
    (reply,) = send(client, op="call_service", service="/rosapi/topic_type", args={"topic": topic})
    assert reply["result"] is True
    kind: str = reply["values"]["type"]
    return kind


def topics(client: RosbridgeSession) -> dict[str, str]:
    (reply,) = send(client, op="call_service", service="/rosapi/topics_and_raw_types", args={})
    values = reply["values"]
    return dict(zip(values["topics"], values["typedefs_full_text"], strict=True))


@pytest.mark.parametrize(
    ("flavour", "header"),
    [
        ("1", "MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id"),
        ("2", "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id"),
    ],
)
def test_rosapi_lists_a_camera_topic_with_its_full_definition(
    flavour: RosFlavour, header: str
) -> None:
    server = hub(flavour)
    publisher = session(server)
    kind = "sensor_msgs/Image" if flavour == "1" else "sensor_msgs/msg/Image"
    camera(publisher, kind)
    assert topic_type(publisher, TOPIC) == kind
    text = topics(publisher)[TOPIC]
    assert text.startswith("std_msgs/Header header\nuint32 height\nuint32 width\n")
    assert header in text
    if flavour == "2":
        assert text.endswith("MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec")


def test_a_topic_nobody_uses_any_more_is_forgotten() -> None:
    server = hub()
    publisher, watcher = session(server), session(server)
    camera(publisher)
    send(watcher, op="subscribe", topic=TOPIC)
    publisher.close()
    assert topic_type(watcher, TOPIC) != ""  # still subscribed to
    send(watcher, op="unsubscribe", topic=TOPIC)
    assert topic_type(watcher, TOPIC) == ""


def test_a_frame_that_cannot_be_json_is_not_sent(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.ERROR)
    assert encode({"op": "publish", "msg": {"x": math.nan}}, False) is None
    assert "not sending a 'publish' message" in caplog.text
    assert encode({"op": "publish", "msg": {"d": b"\x00\x01"}}, False) == (
        '{"op":"publish","msg":{"d":"AAE="}}'
    )
