"""The camera's messages (app/protocol/camera.py): their shapes in JSON and CBOR, both ROS
spellings of a header, and which type a camera topic carries."""

from __future__ import annotations

import base64

import pytest

from app.protocol.camera import (
    CameraMessageError,
    CameraTypeError,
    CompressedImage,
    Image,
    camera_type,
    choose_type,
    parse,
    type_by_name,
)

PIXELS = bytes(range(12))


def raw(data: object, **header: object) -> dict[str, object]:
    return {
        "header": {"stamp": {"sec": 5, "nanosec": 250_000_000}, "frame_id": "cam", **header},
        "height": 2,
        "width": 2,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": 6,
        "data": data,
    }


@pytest.mark.parametrize(
    "data",
    [base64.b64encode(PIXELS).decode(), PIXELS, list(PIXELS)],
    ids=["json-base64", "cbor-bytes", "list-of-ints"],
)
def test_data_reads_as_the_same_bytes_however_it_came(data: object) -> None:
    image = parse("sensor_msgs/Image", raw(data))
    assert isinstance(image, Image)
    assert image.data == PIXELS
    assert (image.width, image.height, image.step, image.encoding) == (2, 2, 6, "rgb8")


@pytest.mark.parametrize(
    ("data", "says"),
    [
        ("not base64!", "not base64"),
        ("QUI", "not base64"),  # its padding missing
        ([1, 2, 256], "0..255"),
        ([1, True], "0..255"),
        (12, "uint8[] data must be"),
    ],
)
def test_data_that_is_no_uint8_array_is_refused_naming_the_field(data: object, says: str) -> None:
    with pytest.raises(CameraMessageError, match=r"field 'data'") as refused:
        parse("sensor_msgs/Image", raw(data))
    assert says in str(refused.value)


def test_both_ros_spellings_of_a_stamp_give_its_seconds() -> None:
    ros2 = parse("sensor_msgs/CompressedImage", {"header": {"stamp": {"sec": 7, "nanosec": 5}}})
    ros1 = parse(
        "sensor_msgs/CompressedImage", {"header": {"seq": 3, "stamp": {"secs": 7, "nsecs": 5}}}
    )
    assert ros2.header.stamp.seconds == ros1.header.stamp.seconds == pytest.approx(7.000000005)
    # A message with no header at all has the zero stamp rosbridge fills in.
    assert parse("sensor_msgs/CompressedImage", {}).header.stamp.seconds == 0.0


def test_a_stamp_in_both_spellings_is_refused() -> None:
    with pytest.raises(CameraMessageError, match="not both"):
        parse("sensor_msgs/Image", raw(PIXELS, stamp={"sec": 1, "nsecs": 2}))


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"height": "2"}, "height"),
        ({"width": -1}, "width"),
        ({"step": 2**32}, "step"),
        ({"encoding": 8}, "encoding"),
        ({"extra": 1}, "extra"),
    ],
)
def test_a_field_of_the_wrong_type_or_an_unknown_one_is_refused(
    change: dict[str, object], field: str
) -> None:
    with pytest.raises(CameraMessageError, match=f"field '{field}'"):
        parse("sensor_msgs/Image", {**raw(PIXELS), **change})


def test_compressed_image_reads_format_and_data() -> None:
    image = parse("sensor_msgs/CompressedImage", {"format": "jpeg", "data": PIXELS})
    assert isinstance(image, CompressedImage)
    assert (image.format, image.data) == ("jpeg", PIXELS)


def test_camera_types_in_either_spelling() -> None:
    assert camera_type("sensor_msgs/msg/CompressedImage") == "sensor_msgs/CompressedImage"
    assert camera_type("sensor_msgs/Image") == "sensor_msgs/Image"
    assert camera_type("sensor_msgs/msg/Image") == "sensor_msgs/Image"
    assert camera_type("sensor_msgs/msg/CameraInfo") is None
    assert camera_type("") is None


def test_a_topic_ending_in_compressed_carries_compressed_images() -> None:
    assert type_by_name("/camera/image/compressed") == "sensor_msgs/CompressedImage"
    assert type_by_name("/camera/image_raw/compressed/") == "sensor_msgs/CompressedImage"
    assert type_by_name("/camera/image_raw") == "sensor_msgs/Image"
    assert type_by_name("/camera/compressed_view") == "sensor_msgs/Image"


def test_the_type_comes_from_rosapi_then_the_description_then_the_name() -> None:
    topic = "/camera/image/compressed"
    assert choose_type(topic, "sensor_msgs/msg/Image", "sensor_msgs/CompressedImage") == (
        "sensor_msgs/Image",
        "rosapi",
    )
    assert choose_type(topic, "", "sensor_msgs/Image") == ("sensor_msgs/Image", "description")
    assert choose_type(topic, None, None) == ("sensor_msgs/CompressedImage", "name")


def test_a_topic_rosapi_says_is_no_image_is_refused_in_one_line() -> None:
    with pytest.raises(CameraTypeError) as refused:
        choose_type("/scan", "sensor_msgs/msg/LaserScan", None)
    assert str(refused.value) == (
        "/scan carries sensor_msgs/msg/LaserScan, not a camera image "
        "(sensor_msgs/CompressedImage or sensor_msgs/Image)"
    )
