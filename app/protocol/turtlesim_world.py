"""The turtlesim world: a square of ``WORLD_SIZE`` metres, origin bottom-left, y up.

The terrain centre (where turtle1 spawns, and where a goal in the middle of the frame lands) is
half of it, written as turtlesim and the thesis write it.
"""

from __future__ import annotations

from typing import Final

WORLD_SIZE: Final = 11.088889
TERRAIN_CENTRE: Final = 5.544445
