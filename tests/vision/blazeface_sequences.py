"""Shared cases for BlazeFace decoding, run by blazeface.py here and by blazeface.js in a page.

``RULE`` states the numbers the rule promises, written out rather than computed by either side
(each twin is checked against it); ``script`` makes seeded random model outputs, letterboxes and
frames on which the two twins must agree to the last bit (:func:`run` is the Python side).
"""

from __future__ import annotations

import math
import random
from typing import Any

from app.vision import blazeface

SHORT_RANGE = [{"stride": 8, "perCell": 2}, {"stride": 16, "perCell": 6}]
FULL_RANGE = [{"stride": 4, "perCell": 1}]


def layers(spec: list[dict[str, int]]) -> list[blazeface.AnchorLayer]:
    return [blazeface.AnchorLayer(layer["stride"], layer["perCell"]) for layer in spec]


def _raw(anchor: int, values: dict[int, float], count: int) -> list[float]:
    """A regressors output of ``count`` anchors, zero but for ``values`` of one anchor."""
    raw = [0.0] * (count * blazeface.COORDS)
    for k, v in values.items():
        raw[anchor * blazeface.COORDS + k] = v
    return raw


# The rule itself. Anchors: short range 16x16x2 + 8x8x6 = 896, full range 48x48 = 2304, centred
# in their cells. A 640x480 frame in a 128 input: scale 0.2, 128x96 written. The passes of a
# 640x480 frame with tiles 0.35 of its width (224 px) overlapping by 0.3: the frame, then 4 x 3
# tiles from edge to edge; a 1280x960 frame the same tiles twice as large; a frame within one
# tile, none. Around a 40x40 box at (300, 200) with margin 0.5: an 80-px square centred on it,
# moved inside the frame near an edge. A logit of 0 scores 0.5; anchor 0 (centre (4, 4)) with dx 4,
# dy 2, w 20, h 10 in a 0.2 letterbox is the box (-10, 5, 100, 50) on the frame (it may cross
# the edge), and a keypoint at (+1, -1) the point (25, 15); a tile at (100, 50) moves both.
RULE: dict[str, Any] = {
    "anchors": [
        [SHORT_RANGE, 128, 896, [4.0, 4.0], [120.0, 120.0]],
        [FULL_RANGE, 192, 2304, [2.0, 2.0], [190.0, 190.0]],
    ],
    "letterbox": [
        [[0, 0, 640, 480], 128, [0.2, 128, 96]],
        [[10, 20, 100, 50], 128, [1.28, 128, 64]],
    ],
    "passes": [
        [
            [640, 480, 0.35, 0.3],
            [[0, 0, 640, 480]]
            + [[x, y, 224, 224] for y in (0, 128, 256) for x in (0, 139, 277, 416)],
        ],
        [
            [1280, 960, 0.35, 0.3],
            [[0, 0, 1280, 960]]
            + [[x, y, 448, 448] for y in (0, 256, 512) for x in (0, 277, 555, 832)],
        ],
        [[200, 150, 1.0, 0.3], [[0, 0, 200, 150]]],
        [[640, 480, 0.0, 0.3], [[0, 0, 640, 480]]],
    ],
    "around": [
        [[[300, 200, 40, 40], 0.5, 640, 480], [280, 180, 80, 80]],
        [[[0, 450, 40, 30], 0.5, 640, 480], [0, 400, 80, 80]],
        [[[0, 0, 600, 600], 0.5, 640, 480], [0, 0, 640, 480]],
    ],
    "decode": [
        # [scores, raw, layers, input, region, threshold] -> [[box, score, first keypoint]...]
        [
            [0.0] + [-10.0] * 895,
            _raw(0, {0: 4.0, 1: 2.0, 2: 20.0, 3: 10.0, 4: 1.0, 5: -1.0}, 896),
            SHORT_RANGE,
            128,
            [0, 0, 640, 480],
            0.5,
            [[[-10, 5, 100, 50], 0.5, [25.0, 15.0]]],
        ],
        [
            [0.0] + [-10.0] * 895,
            _raw(0, {0: 4.0, 1: 2.0, 2: 20.0, 3: 10.0, 4: 1.0, 5: -1.0}, 896),
            SHORT_RANGE,
            128,
            [100, 50, 640, 480],
            0.5,
            [[[90, 55, 100, 50], 0.5, [125.0, 65.0]]],
        ],
        # Below the threshold: nothing.
        [[-0.1] * 896, [0.0] * (896 * 16), SHORT_RANGE, 128, [0, 0, 640, 480], 0.5, []],
    ],
    # [boxes, scores, overlap, min size] -> kept indices, best first: 1 is dropped under 0
    # (IoU 0.68), 2 overlaps nothing, 3 is too small, equal scores keep the earlier.
    "suppress": [
        [
            [[0, 0, 100, 100], [10, 10, 100, 100], [300, 300, 50, 50], [0, 0, 10, 10]],
            [0.9, 0.8, 0.95, 0.99],
            0.3,
            16,
            [2, 0],
        ],
        [[[0, 0, 40, 40], [0, 0, 40, 40]], [0.7, 0.7], 0.3, 0, [0]],
    ],
}


def script(seed: int) -> list[dict[str, Any]]:
    """Seeded cases: model outputs (a few anchors above the threshold, several overlapping),
    the part of a frame they came from, and NMS parameters."""
    rng = random.Random(seed)
    cases = []
    for _ in range(12):
        spec = rng.choice([SHORT_RANGE, FULL_RANGE])
        size = 128 if spec is SHORT_RANGE else 192
        count = len(blazeface.anchors(size, layers(spec)))
        scores = [rng.uniform(-8.0, -1.0) for _ in range(count)]
        raw = [rng.uniform(-3.0, 3.0) for _ in range(count * blazeface.COORDS)]
        hot = rng.sample(range(count), 12)
        for i in hot:
            scores[i] = rng.uniform(-1.0, 6.0)
            raw[i * blazeface.COORDS + 2] = raw[i * blazeface.COORDS + 3] = rng.uniform(6, 60)
        # Neighbours of a hot anchor with a near box: what NMS is for.
        for i in hot[:4]:
            j = (i + 1) % count
            scores[j] = scores[i] - rng.uniform(0.0, 1.0)
            raw[j * 16 : j * 16 + 16] = [v + rng.uniform(-1, 1) for v in raw[i * 16 : i * 16 + 16]]
        w, h = rng.randint(50, 640), rng.randint(50, 480)
        region = [rng.randint(0, 640 - w), rng.randint(0, 480 - h), w, h]
        cases.append(
            {
                "layers": spec,
                "input": size,
                "scores": scores,
                "raw": raw,
                "region": region,
                "threshold": rng.choice([0.5, 0.6, 0.7]),
                "overlap": rng.choice([0.3, 0.5]),
                "minSize": rng.choice([0, 16]),
            }
        )
    return cases


def run(case: dict[str, Any]) -> list[list[Any]]:
    """The Python side on one case: the kept faces as [box, score, keypoints], best first."""
    centres = blazeface.anchors(case["input"], layers(case["layers"]))
    fit = blazeface.letterbox(tuple(case["region"]), case["input"])  # type: ignore[arg-type]
    faces = blazeface.decode(case["scores"], case["raw"], centres, fit, case["threshold"])
    kept = blazeface.suppress(faces, case["overlap"], case["minSize"])
    return [[list(f.box), f.score, [list(p) for p in f.keypoints]] for f in kept]


def close(a: float, b: float) -> bool:
    """Equal to the last bits a different order of float operations may change."""
    return math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-9)
