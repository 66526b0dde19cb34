"""The frame tag: a vehicle frame's number, stamped into its pixels (docs/contracts.md).

A row of square blocks along the top edge, each ``floor(width / blocks_per_width)`` px;
``marker_blocks`` marker blocks (white, black), then ``bits`` bits of the frame number, most
significant first.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final


@dataclass(frozen=True)
class FrameTagLayout:
    """Where the tag's blocks are and how many (the defaults are the contract's)."""

    blocks_per_width: int = 40
    marker_blocks: int = 2
    bits: int = 24


LAYOUT: Final = FrameTagLayout()
