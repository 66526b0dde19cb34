"""BlazeFace decoding (app/vision/blazeface.py) follows the rule stated in
tests/vision/blazeface_sequences.py; its JS twin is checked on the same cases in
e2e/test_blazeface_js.py."""

from __future__ import annotations

import pytest

from app.resources import OPERATIONS_SPEC
from app.vision import blazeface
from app.vision.spec import DnnOperation, load_spec
from tests.vision import blazeface_sequences as seq


def test_anchors_follow_the_rule() -> None:
    for spec, size, count, first, last in seq.RULE["anchors"]:
        centres = blazeface.anchors(size, seq.layers(spec))
        assert len(centres) == count
        assert list(centres[0]) == first and list(centres[-1]) == last


def test_letterbox_passes_and_windows_follow_the_rule() -> None:
    for region, size, (scale, width, height) in seq.RULE["letterbox"]:
        fit = blazeface.letterbox(tuple(region), size)
        assert (fit.scale, fit.width, fit.height) == (pytest.approx(scale), width, height)
    for args, want in seq.RULE["passes"]:
        assert [list(p) for p in blazeface.passes(*args)] == want
    for (box, margin, width, height), want in seq.RULE["around"]:
        assert list(blazeface.around(tuple(box), margin, width, height) or []) == want


def test_decode_and_suppress_follow_the_rule() -> None:
    for scores, raw, spec, size, region, threshold, want in seq.RULE["decode"]:
        fit = blazeface.letterbox(tuple(region), size)
        centres = blazeface.anchors(size, seq.layers(spec))
        faces = blazeface.decode(scores, raw, centres, fit, threshold)
        assert [[list(f.box), f.score, list(f.keypoints[0])] for f in faces] == want
    for boxes, scores, overlap, min_size, want in seq.RULE["suppress"]:
        faces = [
            blazeface.Face(box=tuple(b), score=s, keypoints=())
            for b, s in zip(boxes, scores, strict=True)
        ]
        kept = blazeface.suppress(faces, overlap, min_size)
        assert [next(i for i, f in enumerate(faces) if f is k) for k in kept] == want


def test_the_seeded_cases_exercise_every_step() -> None:
    kept = [seq.run(case) for seed in (1, 2) for case in seq.script(seed)]
    assert all(kept) and any(len(k) > 1 for k in kept)
    # NMS dropped some of the anchors above the threshold.
    raw_counts = [
        sum(blazeface.sigmoid(s) >= case["threshold"] for s in case["scores"])
        for seed in (1, 2)
        for case in seq.script(seed)
    ]
    assert sum(raw_counts) > sum(len(k) for k in kept)


def test_the_operation_declares_the_short_range_model() -> None:
    op = load_spec(OPERATIONS_SPEC).op("face_dnn")
    assert isinstance(op, DnnOperation)
    params = op.params
    assert params.model == "face_detection_short_range.tflite" and params.input_size == 128
    layers = [blazeface.AnchorLayer(a.stride, a.per_cell) for a in params.anchors]
    assert len(blazeface.anchors(params.input_size, layers)) == 896
