"""The flame of the generated scenes: the agent's synthetic video and the simulated arena's
camera draw the same one, so that the fire operation finds both."""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

Image = npt.NDArray[np.uint8]

# Flame colours, outside in (RGB): red-orange, orange, yellow. All lie inside the fire
# operation's HSV ranges (app/vision/operations.json); a pale core would not.
FLAME_LAYERS = ((230, 60, 20), (255, 140, 20), (255, 215, 70))


def draw_flame(rgb: Image, cx: float, cy: float, frame: int, full: float | None = None) -> None:
    """A flickering flame centred on (``cx``, ``cy``) pixels, drawn into ``rgb`` in place;
    ``full`` pixels high at most (by default a seventh of the image's height, 12 at least).

    A teardrop per colour layer, the tip swaying and the height breathing from frame to frame;
    its centre stays put so the target it gives does not wander. Colours are RGB;
    :func:`draw_flame_bgr` draws the same flame into a BGR image.
    """
    _draw(rgb, cx, cy, frame, full, FLAME_LAYERS)


def draw_flame_bgr(bgr: Image, cx: float, cy: float, frame: int, full: float | None = None) -> None:
    """:func:`draw_flame` into a BGR image."""
    _draw(bgr, cx, cy, frame, full, tuple((b, g, r) for r, g, b in FLAME_LAYERS))


def _draw(
    image: Image,
    cx: float,
    cy: float,
    frame: int,
    full: float | None,
    layers: tuple[tuple[int, int, int], ...],
) -> None:
    height = max(12, image.shape[0] // 7) if full is None else full
    flicker = 1.0 + 0.08 * math.sin(frame * 1.3)
    sway = 0.12 * math.sin(frame * 0.7)
    for i, colour in enumerate(layers):
        scale = 1.0 - 0.28 * i
        h = height * scale * flicker
        w = 0.55 * height * scale
        # The teardrop is heavier at the bottom: lift it so its centroid sits on (cx, cy).
        base_y = cy + 0.38 * height - (height - h) * 0.1
        bulb_y = base_y - 0.3 * h
        tip = (cx + sway * w, base_y - h)
        left = (cx - w / 2, bulb_y)
        right = (cx + w / 2, bulb_y)
        cv2.ellipse(
            image,
            (round(cx), round(bulb_y)),
            (max(1, round(w / 2)), max(1, round(0.3 * h))),
            0,
            0,
            360,
            colour,
            -1,
        )
        points = np.array([left, tip, right], dtype=np.float64).round().astype(np.int32)
        cv2.fillPoly(image, [points], colour)
