"""The frame tag (app/protocol/frametag.py): the contract's layout, and what reads back.

The layout's numbers are stated here as docs/contracts.md states them, not taken from the module:
a change to the layout is a change to the contract, which every decoder must follow.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.protocol import frametag


def test_a_640_wide_frame_has_16_pixel_blocks_marker_then_bits_most_significant_first() -> None:
    pixels = np.full((480, 640, 3), 90, np.uint8)
    frametag.stamp(pixels, 0b1011)
    assert frametag.block_size(640) == 16

    def block(i: int) -> np.ndarray:
        return pixels[0:16, 16 * i : 16 * (i + 1)]

    assert (block(0) == 255).all() and (block(1) == 0).all()  # the marker: white, black
    # 24 bits after the marker, most significant first: 0b1011 is the last four.
    bits = [int((block(i) == 255).all()) for i in range(2, 26)]
    assert bits == [0] * 20 + [1, 0, 1, 1]
    assert all((block(i) == 0).all() or (block(i) == 255).all() for i in range(2, 26))
    # Nothing below the top row of blocks nor right of the last block is touched.
    assert (pixels[16:] == 90).all() and (pixels[:, 26 * 16 :] == 90).all()


@pytest.mark.parametrize("frame", [0, 1, 2, 255, 4096, 123_456, 2**24 - 1])
@pytest.mark.parametrize("width", [80, 320, 641, 1280])
def test_round_trip(frame: int, width: int) -> None:
    rgb = np.full((max(48, width * 3 // 4), width, 3), 90, np.uint8)
    frametag.stamp(rgb, frame)
    assert frametag.read(rgb) == frame
    # A luma plane (H×W) reads as its RGB frame does.
    luma = np.full(rgb.shape[:2], 90, np.uint8)
    frametag.stamp(luma, frame)
    assert frametag.read(luma) == frame


def test_the_number_wraps_at_24_bits() -> None:
    rgb = np.zeros((480, 640, 3), np.uint8)
    frametag.stamp(rgb, 2**24 + 5)
    assert frametag.read(rgb) == 5


def test_only_the_inner_half_of_each_block_is_read() -> None:
    # A codec smears block edges: at their worst, each edge reads as the opposite of its block.
    rgb = np.full((480, 640, 3), 90, np.uint8)
    frametag.stamp(rgb, 0xA5A5A5)
    edges = np.ones((16, 16), bool)
    edges[4:12, 4:12] = False
    mask = np.tile(edges, (1, 40))
    rgb[:16][mask] = 255 - rgb[:16][mask]
    assert frametag.read(rgb) == 0xA5A5A5


def test_untagged_or_too_small_frames_read_as_none() -> None:
    assert frametag.read(np.full((480, 640, 3), 200, np.uint8)) is None
    assert frametag.read(np.zeros((480, 640, 3), np.uint8)) is None
    # Blocks under 2 pixels (a frame under 80 wide) or a frame shorter than a block: no tag.
    small = np.zeros((48, 79, 3), np.uint8)
    frametag.stamp(small, 7)
    assert frametag.read(small) is None
    short = np.zeros((40, 640, 3), np.uint8)
    frametag.stamp(short, 7)
    assert frametag.read(short[:15]) is None


def test_a_block_is_white_from_a_mean_of_128_up() -> None:
    # The contract's threshold, at its edge: every black block's inner half at 127 and every
    # white one's at 128 (a codec's greys either side of the middle) still read as stamped.
    rgb = np.zeros((480, 640, 3), np.uint8)
    frametag.stamp(rgb, 0xA5A5A5)
    top = rgb[:16]
    inner = np.zeros(top.shape[:2], bool)
    inner[4:12] = np.tile(np.r_[np.zeros(4, bool), np.ones(8, bool), np.zeros(4, bool)], 40)
    white = top[..., 0] == 255
    top[inner & white] = 128
    top[inner & ~white] = 127
    assert frametag.read(rgb) == 0xA5A5A5
    # One grey level down, the white blocks read black: the marker's first one among them.
    top[inner & white] = 127
    assert frametag.read(rgb) is None
