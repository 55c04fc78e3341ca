"""The JSON Schemas of the camera, hints and result files (``jaxlimb/schemas``): valid schemas, the one statement of
the keys the readers take, every example file of the repository valid, and one-line errors naming the key path."""

from __future__ import annotations

import json
import re
import warnings
from dataclasses import fields
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jsonschema import Draft202012Validator

from jaxlimb._schema import SCHEMA_NAMES, load_schema, schema_keys, validate
from jaxlimb.cli import main
from jaxlimb.errors import ConfigError, HintsKeyWarning
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.hints import Hints

ROOT = Path(__file__).resolve().parents[2]
CAMERA = {"focal_length_mm": 16.0, "pixel_pitch_mm": 0.0022, "rows": 96, "cols": 128}


@pytest.mark.parametrize("name", SCHEMA_NAMES)
def test_each_schema_is_a_valid_draft_2020_12_schema_shipped_as_package_data(name):
    schema = load_schema(name)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    Draft202012Validator.check_schema(schema)
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert '"schemas/*.json"' in pyproject and '"jsonschema>=' in pyproject


def test_the_schemas_keys_are_the_constructors_parameters():
    assert set(schema_keys("camera")) == {f.name for f in fields(Camera)}
    assert set(schema_keys("hints")) == {f.name for f in fields(Hints)}


_SCALAR = st.one_of(st.none(), st.booleans(), st.integers(-3, 200_000), st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([0, 0.0, 1, 2, 32, 33, 1e7, 1e7 + 1, 1000.0, 10.0, 10.5, -0.0, 1e-300]),
                    st.text(max_size=3))
_VALUE = st.one_of(_SCALAR, st.lists(_SCALAR, max_size=4), st.lists(st.lists(_SCALAR, min_size=3, max_size=3),
                                                                     min_size=2, max_size=4),
                   st.sampled_from([[[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0.0, 0.0, 1.0], [1.0, 2.0, 3.0], [5.0, 7.0]]))


def _accepts(build, d: dict) -> bool:
    try:
        build(d)
    except ConfigError:
        return False
    return True


_VALIDATORS = {name: Draft202012Validator(load_schema(name)) for name in ("camera", "hints")}


@settings(max_examples=250, deadline=None, derandomize=True, database=None)
@given(camera=st.dictionaries(st.sampled_from(schema_keys("camera")), _VALUE, max_size=4),
       hints=st.dictionaries(st.sampled_from(schema_keys("hints")), _VALUE, max_size=4))
def test_the_constructors_are_at_least_as_strict_as_the_schemas(camera, hints):
    """What ``Camera(...)`` / ``Hints(...)`` accept is valid against the schema, so the readers may leave the
    ``jsonschema`` validator to the files a constructor refuses (jaxlimb/_schema.py)."""
    camera = {**CAMERA, **camera}
    if _accepts(lambda d: Camera(**d), camera):
        assert _VALIDATORS["camera"].is_valid(camera), camera
    if _accepts(lambda d: Hints(**{k: v for k, v in d.items() if v is not None}), hints):
        assert _VALIDATORS["hints"].is_valid(hints), hints


def _json_blocks(text: str) -> list[dict]:
    out = []
    for block in re.findall(r"```json[^\n]*\n(.*?)```", text, re.S):
        if '"..."' in block:
            continue  # a shortened example
        try:
            obj = json.loads(block)
        except json.JSONDecodeError:
            continue  # not an object of ours
        if isinstance(obj, dict):
            out.append(obj)
    return out


def _example_files() -> list[tuple[str, str, dict]]:
    """Every camera and hints object the documentation and the test fixtures show, with where it is."""
    from fuzz.conftest import CAMERA as FUZZ_CAMERA  # tests/ is on the path (its sub-folders are packages)
    from fuzz.conftest import HINTS as FUZZ_HINTS
    from pipeline._scenes import SMALL_CAMERA

    found = [("camera", "tests/fuzz/conftest.py", FUZZ_CAMERA), ("hints", "tests/fuzz/conftest.py", FUZZ_HINTS),
             ("camera", "tests/pipeline/_scenes.py", SMALL_CAMERA.to_dict()),
             ("camera", "Camera.default().to_dict()", Camera.default().to_dict())]
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    for page in pages:
        for obj in _json_blocks(page.read_text()):
            kind = "camera" if "focal_length_mm" in obj else "hints" if set(obj) <= set(schema_keys("hints")) else None
            if kind:
                found.append((kind, str(page.relative_to(ROOT)), obj))
    return found


def test_every_example_camera_and_hints_file_validates():
    examples = _example_files()
    where = {w for _, w, _ in examples}
    assert "docs/formats.md" in where and sum(k == "hints" and w == "docs/formats.md" for k, w, _ in examples) == 2
    for kind, where, obj in examples:
        validate(obj, kind, f"{kind} of {where}")
        (Camera if kind == "camera" else Hints).from_dict(obj)


def test_a_json_block_of_the_docs_that_is_a_result_validates():
    shown = [o for p in [ROOT / "docs" / "formats.md"] for o in _json_blocks(p.read_text()) if "status" in o]
    assert shown
    for obj in shown:
        validate(obj, "result", "result")


@pytest.mark.parametrize(("bad", "message"), [
    ({"focal_length": 16.0}, "camera has unknown keys ['focal_length'] ('focal_length': did you mean "
                             "'focal_length_mm'?)"),
    ({"k_1": 0.1}, "'k_1': did you mean 'k1'?"),
    ({"principal_point_rc": [47.5, "63.5"]}, "camera `principal_point_rc[1]` must be a number, got str '63.5'"),
    ({"principal_point_rc": [47.5]}, "camera `principal_point_rc` must be a list of 2 items, got [47.5]"),
    ({"rows": True}, "camera `rows` must be an integer, got bool True"),
    ({"pixel_pitch_mm": 0}, "camera `pixel_pitch_mm` must be a number in (0, 1000], got 0"),
    ({"k2": None}, "camera `k2` must be a number, got null"),
])
def test_camera_errors_name_the_key_path(bad, message):
    with pytest.raises(ConfigError) as e:
        Camera.from_dict({**CAMERA, **bad})
    assert message in str(e.value) and "\n" not in str(e.value)


def test_a_camera_without_its_required_keys():
    with pytest.raises(ConfigError, match=re.escape("camera is missing keys ['rows', 'cols']")):
        Camera.from_dict({"focal_length_mm": 16.0, "pixel_pitch_mm": 0.0022})


@pytest.mark.parametrize(("bad", "message"), [
    ({"R_body_to_camera": [[1, 0, 0], [0, 1, 0], [0, 0, "1"]]}, "hints `R_body_to_camera[2][2]` must be a number"),
    ({"bit_depth": 33}, "hints `bit_depth` must be an integer in [1, 32], got 33"),
    ({"body": " "}, "hints `body` must be a non-blank string"),
    ({"body_radii_km": [1.0, 1.0, 0.0]}, "hints `body_radii_km[2]` must be a number > 0, got 0.0"),
])
def test_hints_errors_name_the_key_path(bad, message):
    with pytest.raises(ConfigError) as e:
        Hints.from_dict(bad)
    assert message in str(e.value)


def test_hints_null_is_absent_and_an_unknown_key_is_ignored_with_a_warning_if_it_resembles_one():
    assert Hints.from_dict({"range_prior_km": None, "filter_state": [1, 2]}) == Hints()
    with pytest.warns(HintsKeyWarning, match="'expected_radius' .* did you mean 'expected_radius_px'"):
        Hints.from_dict({"expected_radius": 30.0})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Hints.from_dict({"body": "moon", "note": "k=12"})


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    d = tmp_path_factory.mktemp("schema")
    y, x = np.mgrid[:96, :128]
    cv2.imwrite(str(d / "img.png"), (5 + 200 / (1 + np.exp(np.hypot(y - 50.0, x - 60.0) - 30.0))).astype(np.uint8))
    return d


@pytest.mark.parametrize("as_json", [True, False])
def test_cli_misspelt_camera_key_is_exit_2_with_the_suggestion(frame, capsys, as_json):
    cam = frame / "cam.json"
    cam.write_text(json.dumps({**CAMERA, "pixel_pitch": 0.0022}))
    code = main(["locate", str(frame / "img.png"), "--camera", str(cam), *(["--json"] if as_json else [])])
    out, err = capsys.readouterr()
    assert code == 2 and "Traceback" not in out + err
    if as_json:
        obj = json.loads(out)
        assert obj["check"] == "bad_config" and "'pixel_pitch': did you mean 'pixel_pitch_mm'?" in obj["message"]
        validate(obj, "result", "result")  # an error record is a result too
    else:
        assert out == "" and len(err.splitlines()) == 1
        assert err.startswith("jaxlimb: error: camera has unknown keys ['pixel_pitch'] ('pixel_pitch': did you mean "
                              "'pixel_pitch_mm'?)")


def test_cli_wrong_type_in_hints_is_exit_2_naming_the_key_path(frame, capsys):
    hints = frame / "hints.json"
    hints.write_text(json.dumps({"body": "moon", "expected_center_rc": [50, "sixty"]}))
    code = main(["locate", str(frame / "img.png"), "--hints", str(hints)])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err == "jaxlimb: error: hints `expected_center_rc[1]` must be a number, got str 'sixty'\n"


def test_result_schema_refuses_what_a_record_never_holds():
    ok = {"status": "ok", "center_rc": [1.0, 2.0], "k": 1.0, "ymax": 1.0, "ymin": 0.0, "covariance": {},
          "iterations": 3, "solver": "lm", "front_end": "gradient", "n_pixels": 10}
    validate(ok, "result", "result")
    for bad in ({**ok, "center_rc": [1.0]}, {**ok, "radius": 3.0}, {k: v for k, v in ok.items() if k != "k"},
                {"status": "error", "check": "bad_config"}):
        with pytest.raises(ConfigError):
            validate(bad, "result", "result")
