"""The operations spec: what is accepted, what is refused at start-up, and how it is served."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.resources import OPERATIONS_SPEC
from app.server.app import create_app
from app.server.config import Settings
from app.server.serve import RunningServer
from app.vision.spec import CASCADE_DIR, SpecError, load_spec

SPEC = OPERATIONS_SPEC


def spec_with(tmp_path: Path, change: Any) -> Path:
    """A copy of the shipped spec after ``change(raw)`` edits it, written to ``tmp_path``."""
    raw = json.loads(SPEC.read_text())
    change(raw)
    path = tmp_path / "operations.json"
    path.write_text(json.dumps(raw))
    return path


def op(raw: dict[str, Any], op_id: str) -> dict[str, Any]:
    entry: dict[str, Any] = next(o for o in raw["operations"] if o["id"] == op_id)
    return entry


def test_shipped_spec_has_the_issue_operations() -> None:
    spec = load_spec(SPEC)
    kinds = {o.id: o.kind for o in spec.operations}
    assert spec.default == "face"
    assert kinds == {
        "face": "cascade",
        "face_small": "cascade",
        "face_dnn": "dnn",
        "body": "cascade",
        "fire": "colour",
    }
    face = spec.op("face")
    assert face.params.cascades == ["haarcascade_frontalface_default.xml"]
    assert "largest" in face.description


def test_each_operation_declares_the_real_height_of_what_it_finds() -> None:
    # A face's box as the simulated arena's faces are scaled (docs/simulated-arena.md; BlazeFace's
    # box is a little shorter than Haar's on the same face, docs/operations.md), a flame's as the
    # arena's flame stands, a standing person's.
    heights = {o.id: o.target_height_m for o in load_spec(SPEC).operations}
    assert heights == {
        "face": 0.24,
        "face_small": 0.24,
        "face_dnn": 0.22,
        "body": 1.7,
        "fire": 0.5,
    }


def test_a_missing_model_is_refused_with_the_op_and_file_named(tmp_path: Path) -> None:
    path = spec_with(
        tmp_path, lambda raw: op(raw, "face_dnn")["params"].update(model="nope.tflite")
    )
    with pytest.raises(SpecError) as error:
        load_spec(path)
    assert "'face_dnn'" in str(error.value) and "nope.tflite" in str(error.value)


def test_thesis_profile_overrides_only_what_it_names() -> None:
    face = load_spec(SPEC).op("face")
    thesis = face.params_for("thesis")
    assert thesis.detect_width is None  # full resolution, no reduction
    assert (thesis.scale_factor, thesis.min_neighbors, thesis.min_size) == (1.1, 3, (0, 0))
    assert thesis.cascades == face.params.cascades
    assert face.params_for("default") == face.params


def test_missing_cascade_is_refused_with_the_op_and_file_named(tmp_path: Path) -> None:
    path = spec_with(
        tmp_path, lambda raw: op(raw, "body")["params"].update(cascades=["haarcascade_nope.xml"])
    )
    with pytest.raises(SpecError) as error:
        load_spec(path)
    message = str(error.value)
    assert "'body'" in message and "haarcascade_nope.xml" in message and str(path) in message


def test_missing_cascade_in_thesis_overrides_is_refused(tmp_path: Path) -> None:
    path = spec_with(
        tmp_path, lambda raw: op(raw, "face")["thesis"].update(cascades=["missing.xml"])
    )
    with pytest.raises(SpecError, match="missing.xml"):
        load_spec(path)


def test_cascade_outside_the_wheel_data_is_refused(tmp_path: Path) -> None:
    # A path would let the spec serve any file through /cascades/.
    outside = str(CASCADE_DIR.parent / "__init__.py")
    path = spec_with(tmp_path, lambda raw: op(raw, "face")["params"].update(cascades=[outside]))
    with pytest.raises(SpecError, match="does not ship"):
        load_spec(path)


def test_unknown_module_is_refused(tmp_path: Path) -> None:
    path = spec_with(tmp_path, lambda raw: op(raw, "fire").update(module="smoke.js"))
    with pytest.raises(SpecError, match=r"'fire'.*smoke\.js"):
        load_spec(path)


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (lambda raw: raw.update(default="dance"), "default operation 'dance'"),
        (lambda raw: raw["operations"].append(raw["operations"][0]), "duplicate operation id"),
        (lambda raw: op(raw, "face")["params"].update(scaleFactr=1.2), "scaleFactr"),
        (lambda raw: op(raw, "face")["params"].update(scaleFactor=1.0), "scaleFactor"),
        (lambda raw: op(raw, "fire").update(kind="smell"), "kind"),
        (lambda raw: op(raw, "fire")["thesis"].update(minArea=0), "minArea"),
        # The real height the onboard law reads a range from: required, positive, in metres.
        (lambda raw: op(raw, "face").pop("targetHeightM"), "targetHeightM"),
        (lambda raw: op(raw, "face").update(targetHeightM=0), "targetHeightM"),
        (lambda raw: op(raw, "fire").update(targetHeightM=-0.5), "targetHeightM"),
        (lambda raw: op(raw, "body").update(targetHeightM=170), "targetHeightM"),
        (lambda raw: op(raw, "body").update(targetHeightM="1.7"), "targetHeightM"),
    ],
)
def test_invalid_entries_are_refused_naming_the_field(
    tmp_path: Path, change: Any, expected: str
) -> None:
    with pytest.raises(SpecError, match=expected):
        load_spec(spec_with(tmp_path, change))


def test_unreadable_and_malformed_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match="cannot read"):
        load_spec(tmp_path / "absent.json")
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    with pytest.raises(SpecError, match="not valid JSON"):
        load_spec(broken)


def test_server_refuses_to_start_with_a_bad_spec(tmp_path: Path) -> None:
    path = spec_with(tmp_path, lambda raw: op(raw, "face")["params"].update(cascades=["gone.xml"]))
    with pytest.raises(SpecError, match="gone.xml"):
        create_app(Settings(operations_spec=path))


def test_routes_serve_the_spec_and_only_its_cascades(server: RunningServer) -> None:
    with httpx.Client(base_url=server.url) as client:
        check_routes(client)


def check_routes(client: httpx.Client) -> None:
    served = client.get("/operations.json").json()
    assert [o["id"] for o in served["operations"]] == [
        "face",
        "face_small",
        "face_dnn",
        "body",
        "fire",
    ]
    # Defaults are filled in, so the browser never has to know them.
    assert served["operations"][0]["params"]["maxSize"] == [0, 0]
    assert served["operations"][0]["targetHeightM"] == 0.24
    xml = client.get("/cascades/haarcascade_fullbody.xml")
    assert xml.status_code == 200
    assert xml.content == (CASCADE_DIR / "haarcascade_fullbody.xml").read_bytes()
    assert client.get("/cascades/haarcascade_eye.xml").status_code == 404
    assert client.get("/cascades/..%2F__init__.py").status_code == 404
