"""A camera message's pixels (vehicle_agent/rosimage.py): each encoding and codec decodes to the
picture that was sent, bad ones are refused in one line, any size is letterboxed into the video."""

from __future__ import annotations

import struct
from typing import Any

import cv2
import numpy as np
import pytest

from app.protocol.camera import parse
from tests.helpers.camera_frames import QUADRANTS, colours, compressed, pattern, pattern_error, raw
from vehicle_agent.rosimage import (
    MAX_PIXELS,
    ImageProblem,
    codec_of,
    encoded_size,
    fit,
    letterbox,
    to_rgb,
)


def image(msg: dict[str, Any]) -> np.ndarray:
    kind = "sensor_msgs/Image" if "encoding" in msg else "sensor_msgs/CompressedImage"
    return to_rgb(parse(kind, msg))


@pytest.mark.parametrize("padding", [0, 5])
@pytest.mark.parametrize("encoding", ["rgb8", "bgr8"])
def test_colour_encodings_decode_to_the_exact_pixels_sent(encoding: str, padding: int) -> None:
    sent = pattern(64, 48, 1234)
    assert np.array_equal(image(raw(sent, encoding, 0.0, padding)), sent)


@pytest.mark.parametrize("padding", [0, 3])
def test_mono8_decodes_to_its_grey_in_all_three_channels(padding: int) -> None:
    sent = pattern(64, 48, 7)
    grey = cv2.cvtColor(sent, cv2.COLOR_RGB2GRAY)
    got = image(raw(sent, "mono8", 0.0, padding))
    assert got.shape == (48, 64, 3)
    assert all(np.array_equal(got[:, :, c], grey) for c in range(3))


def test_row_padding_is_not_taken_for_pixels() -> None:
    # Each row's padding is 0xAB: none of it may show up in the picture.
    sent = np.zeros((4, 6, 3), np.uint8)
    got = image(raw(sent, "rgb8", 0.0, padding=7))
    assert got.shape == (4, 6, 3) and not got.any()


@pytest.mark.parametrize(
    "encoding", ["rgba8", "bgra8", "mono16", "16UC1", "32FC1", "yuv422", "bayer_rggb8", ""]
)
def test_other_encodings_are_refused_in_one_clear_line(encoding: str) -> None:
    msg = {**raw(pattern(8, 6, 0), "rgb8", 0.0), "encoding": encoding}
    with pytest.raises(ImageProblem) as refused:
        image(msg)
    assert refused.value.kind == "encoding"
    assert str(refused.value) == (
        f"encoding {encoding!r} is not one the agent reads (rgb8, bgr8, mono8)"
    )


@pytest.mark.parametrize(
    ("change", "says"),
    [
        ({"height": 7}, "data holds 144 bytes, not height x step = 7 x 24"),  # data too short
        ({"height": 5}, "data holds 144 bytes, not height x step = 5 x 24"),  # data too long
        ({"step": 20, "height": 7}, "step 20 is shorter than a row of 8 rgb8 pixels (24)"),
        ({"width": 0}, "an empty image (0x6)"),
        ({"width": 70_000, "height": 70_000}, "larger than the agent decodes"),
    ],
)
def test_wrong_sizes_are_refused(change: dict[str, int], says: str) -> None:
    msg = {**raw(pattern(8, 6, 0), "rgb8", 0.0), **change}
    with pytest.raises(ImageProblem) as refused:
        image(msg)
    assert refused.value.kind == "size"
    assert says in str(refused.value)


def test_png_decodes_to_the_exact_pixels_sent() -> None:
    sent = pattern(160, 120, 99)
    assert np.array_equal(image(compressed(sent, "png", 0.0)), sent)


@pytest.mark.parametrize(
    "format_", ["jpeg", "bgr8; jpeg compressed bgr8", "rgb8; jpeg compressed bgr8"]
)
def test_jpeg_decodes_to_the_picture_sent_within_its_loss(format_: str) -> None:
    sent = pattern(160, 120, 99)
    got = image(compressed(sent, "jpg", 0.0, format_))
    assert got.shape == sent.shape
    assert pattern_error(got) <= 12


@pytest.mark.parametrize(
    ("format_", "says"),
    [
        ("16UC1; compressedDepth png", "a depth image"),
        ("tiff", "neither jpeg nor png"),
        ("", "neither jpeg nor png"),
    ],
)
def test_formats_other_than_jpeg_and_png_are_refused(format_: str, says: str) -> None:
    with pytest.raises(ImageProblem, match=says) as refused:
        codec_of(format_)
    assert refused.value.kind == "format"


def test_data_of_another_codec_than_its_format_says_is_refused() -> None:
    msg = compressed(pattern(32, 24, 0), "png", 0.0, format_="jpeg")
    with pytest.raises(ImageProblem, match="the data is no jpeg"):
        image(msg)


@pytest.mark.parametrize("keep", [0.3, 0.66, 0.95])
@pytest.mark.parametrize("codec", ["jpg", "png"])
def test_truncated_data_is_refused(codec: str, keep: float) -> None:
    msg = compressed(pattern(160, 120, 5), codec, 0.0)
    cut = msg["data"][: round(len(msg["data"]) * keep)]
    with pytest.raises(ImageProblem, match="does not decode: truncated or corrupt") as refused:
        image({**msg, "data": cut})
    assert refused.value.kind == "corrupt"


def test_garbage_between_a_jpegs_first_and_last_bytes_is_refused() -> None:
    msg = compressed(pattern(160, 120, 5), "jpg", 0.0)
    data = msg["data"]
    garbage = data[:3] + bytes(len(data) - 5) + data[-2:]
    with pytest.raises(ImageProblem) as refused:
        image({**msg, "data": garbage})
    assert refused.value.kind == "corrupt"


@pytest.mark.parametrize("progressive", [False, True])
def test_a_jpegs_size_is_read_from_its_header(progressive: bool) -> None:
    bgr = np.zeros((37, 53, 3), np.uint8)
    flags = [cv2.IMWRITE_JPEG_PROGRESSIVE, int(progressive)]
    ok, jpeg = cv2.imencode(".jpg", bgr, flags)
    assert ok
    assert encoded_size("jpeg", jpeg.tobytes()) == (53, 37)
    ok, png = cv2.imencode(".png", bgr)
    assert encoded_size("png", png.tobytes()) == (53, 37)
    assert encoded_size("jpeg", jpeg.tobytes()[:20]) is None


def test_a_jpeg_claiming_a_huge_picture_is_refused_before_it_is_decoded() -> None:
    msg = compressed(pattern(64, 48, 0), "jpg", 0.0)
    data = bytearray(msg["data"])
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = struct.pack(">HH", 60_000, 60_000)
    assert 60_000 * 60_000 > MAX_PIXELS
    with pytest.raises(ImageProblem, match="60000x60000 picture is larger") as refused:
        image({**msg, "data": bytes(data)})
    assert refused.value.kind == "size"


def test_a_wider_picture_fills_the_width_with_equal_bars_above_and_below() -> None:
    placed = fit(1280, 720, (640, 480))
    assert placed.scaled == (640, 360) and placed.offset == (0, 60)
    picture = np.full((720, 1280, 3), 200, np.uint8)
    frame = letterbox(picture, (640, 480))
    assert frame.shape == (480, 640, 3)
    assert not frame[:60].any() and not frame[420:].any()
    assert (frame[60:420] == 200).all()


def test_a_narrower_picture_is_pillarboxed_and_a_smaller_one_scaled_up() -> None:
    assert fit(480, 480, (640, 480)).offset == (80, 0)
    small = pattern(160, 120, 3)
    frame = letterbox(small, (640, 480))
    assert frame.shape == (480, 640, 3)
    # Scaled four times: each quadrant's colour where it belongs.
    assert colours(frame) == list(QUADRANTS)


def test_a_picture_of_the_videos_size_is_passed_as_it_is() -> None:
    picture = pattern(640, 480, 1)
    assert letterbox(picture, (640, 480)) is picture
