"""The relay's frame-tag decoder (js/core/frame-tag.js) reads what the Python encoder stamps.

The encoder and the contract are app/protocol/frametag.py (tests/protocol/test_frametag.py states
the layout in numbers); the page gets the layout from its config, as the relay's worker does, and
must read every tag the Python side reads, and none where it reads none. The worker's own path
(raw RGBA, I420 frames converted in part) is tests/vision/test_analyzer*.py's.
"""

from __future__ import annotations

import base64
from collections.abc import Iterator

import numpy as np
import pytest
from playwright.sync_api import Page

from app.protocol import frametag
from tests.helpers.served_page import served_page

pytestmark = [pytest.mark.browser]

# Decode every frame ([width, height, base64 RGBA]) with the layout of the page's own config,
# or with these changes to it.
DECODE_ALL = """async ([frames, changes]) => {
  const { PROTOCOL } = await import('/static/js/config.js');
  const { decodeFrameTag } = await import('/static/js/core/frame-tag.js');
  const layout = { ...PROTOCOL.frameTag, ...changes };
  const bytes = (b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
  return frames.map(([w, h, b64]) => decodeFrameTag(layout, w, h, bytes(b64)));
}"""


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with served_page() as opened:
        yield opened


def rgba(width: int, height: int, grey: int = 90) -> np.ndarray:
    frame = np.full((height, width, 4), grey, np.uint8)
    frame[..., 3] = 255
    return frame


def stamped(
    number: int, width: int, height: int = 48, layout: frametag.FrameTagLayout = frametag.LAYOUT
) -> np.ndarray:
    frame = rgba(width, height)
    frametag.stamp(frame[..., :3], number, layout)
    return frame


def decode(
    page: Page, frames: list[np.ndarray], changes: dict[str, int] | None = None
) -> list[int | None]:
    payload = [[f.shape[1], f.shape[0], base64.b64encode(f.tobytes()).decode()] for f in frames]
    decoded: list[int | None] = page.evaluate(DECODE_ALL, [payload, changes or {}])
    return decoded


def test_the_page_reads_every_tag_the_python_encoder_stamps(page: Page) -> None:
    numbers = [0, 1, 2, 255, 4096, 123_456, 0xA5A5A5, 2**24 - 1]
    frames = [stamped(n, w) for w in (80, 320, 640, 641, 1280) for n in numbers]
    assert decode(page, frames) == [frametag.read(f[..., :3]) for f in frames]
    assert decode(page, frames) == numbers * 5


def test_the_page_reads_the_tag_with_the_layout_it_is_given(page: Page) -> None:
    # Another layout, as a change to the config's would be: both sides follow it.
    layout = frametag.FrameTagLayout(blocks_per_width=32, marker_blocks=3, bits=16)
    frames = [stamped(n, 640, layout=layout) for n in (0, 0xBEEF, 2**16 - 1)]
    assert [frametag.read(f[..., :3], layout) for f in frames] == [0, 0xBEEF, 2**16 - 1]
    changes = {"blocksPerWidth": 32, "markerBlocks": 3, "bits": 16}
    assert decode(page, frames, changes) == [0, 0xBEEF, 2**16 - 1]
    # Read with the config's own layout, these frames carry no tag or another number.
    assert decode(page, frames) != [0, 0xBEEF, 2**16 - 1]


def test_the_page_reads_no_tag_where_python_reads_none(page: Page) -> None:
    untagged = [rgba(640, 48, 200), rgba(640, 48, 0), rgba(79, 48)]
    short = stamped(7, 640)[:15]  # shorter than a block
    frames = [*untagged, short]
    assert [frametag.read(f[..., :3]) for f in frames] == [None] * 4
    assert decode(page, frames) == [None] * 4
    # A stamped frame whose marker is not white, black: no tag on either side.
    swapped = stamped(5, 640)
    swapped[:16, :16, :3], swapped[:16, 16:32, :3] = 0, 255
    assert frametag.read(swapped[..., :3]) is None and decode(page, [swapped]) == [None]


def test_both_read_only_the_inner_half_of_each_block(page: Page) -> None:
    # A video codec smears the blocks' edges: at their worst, each edge reads as the opposite
    # of its block, and the tag still reads from the blocks' inner halves.
    frames = []
    for number in (0x0F0F0F, 0x123456, 0xFEDCBA):
        frame = stamped(number, 640)
        edges = np.ones((16, 16), bool)
        edges[4:12, 4:12] = False
        mask = np.tile(edges, (1, 40))
        frame[:16][mask, :3] = 255 - frame[:16][mask, :3]
        frames.append(frame)
    assert decode(page, frames) == [0x0F0F0F, 0x123456, 0xFEDCBA]
    assert [frametag.read(f[..., :3]) for f in frames] == [0x0F0F0F, 0x123456, 0xFEDCBA]
