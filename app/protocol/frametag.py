"""The frame tag: a vehicle frame's number, stamped into its own pixels (docs/contracts.md).

The synthetic video stamps each frame's number so that whoever decodes the video (the relay's
worker, the flight recorder, a test) can say which frame it holds, and the relay can echo it in
its goals: latency is measured frame by frame, across a video codec.

A row of square blocks along the top edge, each ``b = floor(width / blocks_per_width)`` pixels;
block ``i`` spans ``x ∈ [i·b, (i+1)·b)``, ``y ∈ [0, b)``. The first ``marker_blocks`` are the
marker, white then black; then ``bits`` bits of the frame number, most significant first,
white for 1. Reading samples the mean of the inner half of each block (away from its edges, which
a codec blurs) and thresholds at 128; a frame whose marker does not read white, black has no tag.

The pages decode it in the relay's worker from ``config.protocol.frameTag`` (this
:data:`LAYOUT`); ``tests/protocol/test_frametag_js.py`` checks that they read what
:func:`stamp` writes. Pure: works on any numpy array, imports no numpy itself.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    Pixels = npt.NDArray[np.uint8]
else:
    Pixels = Any

WHITE: Final = 255
BLACK: Final = 0


@dataclass(frozen=True)
class FrameTagLayout:
    """Where the tag's blocks are and how many (the defaults are the contract's)."""

    blocks_per_width: int = 40
    # White, then black.
    marker_blocks: int = 2
    bits: int = 24


LAYOUT: Final = FrameTagLayout()


def block_size(width: int, layout: FrameTagLayout = LAYOUT) -> int:
    """Side of one tag block in pixels for a frame ``width`` pixels wide."""
    return width // layout.blocks_per_width


def stamp(pixels: Pixels, frame: int, layout: FrameTagLayout = LAYOUT) -> None:
    """Write ``frame`` (mod 2**bits) into the top row of blocks of ``pixels`` (H×W or H×W×C),
    in place."""
    b = block_size(pixels.shape[1], layout)
    bits = layout.bits
    marker = [WHITE] + [BLACK] * (layout.marker_blocks - 1)
    values = marker + [WHITE if (frame >> (bits - 1 - i)) & 1 else BLACK for i in range(bits)]
    for i, value in enumerate(values):
        pixels[0:b, i * b : (i + 1) * b] = value


def read(pixels: Pixels, layout: FrameTagLayout = LAYOUT) -> int | None:
    """The frame number :func:`stamp` wrote into ``pixels`` (H×W or H×W×C; only the top
    ``block_size`` rows are read), or None when there is no tag."""
    b = block_size(pixels.shape[1], layout)
    if b < 2 or pixels.shape[0] < b:
        return None
    blocks = layout.marker_blocks + layout.bits
    lo, hi = b // 4, b // 4 + max(1, b // 2)
    # The inner square of every block at once (rows, block, columns, channel): the mean of each.
    inner = pixels[lo:hi, : blocks * b].reshape(hi - lo, blocks, b, -1)[:, :, lo:hi]
    white = inner.mean(axis=(0, 2, 3)) >= 128
    if not white[0] or white[1 : layout.marker_blocks].any():
        return None
    value = 0
    for bit in white[layout.marker_blocks :]:
        value = (value << 1) | int(bit)
    return value
