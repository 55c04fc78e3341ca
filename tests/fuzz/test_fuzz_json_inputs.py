"""Hostile camera and hints files for every sub-command that reads them (hypothesis).

One key of a valid camera (hints) file is replaced by a value that cannot be that quantity:
a boolean (``true`` is not 1 mm), a number written as a string, NaN, an infinity, a value out
of range, a list or object, a vector of the wrong length or holding booleans/strings.  Every
case must exit 2 with ``check = bad_config`` and a one-line message naming the key; the
library constructors (:class:`Camera`, :class:`Hints`) must raise ``ConfigError`` naming it.
"""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxlimb.errors import ConfigError
from jaxlimb.geometry.camera import Camera
from jaxlimb.imaging import Hints

from ._cli import assert_refused, run_cli
from .conftest import CAMERA, HINTS

FUZZ = settings(max_examples=15, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

_NOT_A_NUMBER = st.one_of(
    st.booleans(),
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr),  # "3.08": a string, not a number
    st.sampled_from([math.nan, math.inf, -math.inf, None, "", "NaN", [], {}, [1.0], {"value": 1.0}]),
)


def _bad_scalar(lo: float, hi: float | None, integer: bool = False, allow_none: bool = False) -> st.SearchStrategy:
    out = [_NOT_A_NUMBER.filter(lambda v: not (allow_none and v is None)),
           st.floats(max_value=lo, exclude_max=False, allow_nan=False, allow_infinity=False).filter(lambda x: x <= lo)]
    if hi is not None:
        out.append(st.floats(min_value=hi, allow_nan=False, allow_infinity=False).filter(lambda x: x > hi))
    if integer:
        out.append(st.floats(min_value=lo + 0.5, max_value=(hi or 1e6) - 0.5).filter(lambda x: not x.is_integer()))
    return st.one_of(*out)


def _bad_vector(n: int) -> st.SearchStrategy:
    num = st.floats(-1.0, 1.0)
    return st.one_of(
        st.lists(num, min_size=0, max_size=6).filter(lambda v: len(v) != n),
        st.tuples(*([st.booleans()] + [num] * (n - 1))).map(list),
        st.tuples(*([num.map(repr)] + [num] * (n - 1))).map(list),
        st.tuples(*([st.sampled_from([math.nan, math.inf, None])] + [num] * (n - 1))).map(list),
        st.sampled_from(["0 0 1", 1.0, True, {"x": 1}]),
    )


CAMERA_BAD = {
    "focal_length_mm": _bad_scalar(0.0, 1e7),
    "pixel_pitch_mm": _bad_scalar(0.0, 1e3),
    "rows": _bad_scalar(1, 100_000, integer=True),
    "cols": _bad_scalar(1, 100_000, integer=True),
    "principal_point_rc": _bad_vector(2).filter(lambda v: v is not None),
    "k1": _NOT_A_NUMBER.filter(lambda v: v is not None),
}
HINTS_BAD = {
    "expected_radius_px": _bad_scalar(0.0, None, allow_none=True),
    "range_prior_km": _bad_scalar(0.0, None, allow_none=True),
    "expected_radius_uncertainty_frac": _bad_scalar(0.0, 10.0, allow_none=True),
    "atmosphere_km": _NOT_A_NUMBER.filter(lambda v: v is not None),
    "bit_depth": _bad_scalar(0, 32, integer=True, allow_none=True),
    "sun_dir_camera": _bad_vector(3),
    "body_radii_km": _bad_vector(3),
}


def _argv(command: str, f: dict, camera, hints) -> list:
    common = {"camera": ["--camera", camera], "hints": ["--hints", hints] if hints else []}
    return {
        "locate": ["locate", f["moon.png"], *common["camera"], *common["hints"], "--json"],
        "los-locate": ["los", "locate", f["moon.png"], "--db", f["db.npz"], *common["camera"], *common["hints"], "--json"],
        "posterior": ["posterior", f["moon.png"], "--center-rc", "60", "80", "--radius", "30", *common["camera"],
                      *common["hints"], "--json"],
        "navigate": ["navigate", f["moon.png"], *common["camera"], *common["hints"], "--epoch", "2026-01-01T00:00:00Z",
                     "--attitude", "[0, 0, 0, 1]", "--json"],
    }[command]


COMMANDS = ("locate", "los-locate", "posterior", "navigate")


FILES = {"camera": (CAMERA, CAMERA_BAD, Camera.from_dict), "hints": (HINTS, HINTS_BAD, Hints.from_dict)}


@pytest.mark.parametrize("role", sorted(FILES))
@pytest.mark.parametrize("command", COMMANDS)
def test_hostile_camera_or_hints_file_exits_2_naming_the_key(command, role, inputs, tmp_path_factory):
    valid, bad, build = FILES[role]
    path = tmp_path_factory.mktemp(role) / f"{role}.json"

    @FUZZ
    @given(key_value=st.sampled_from(sorted(bad)).flatmap(lambda k: st.tuples(st.just(k), bad[k])))
    def case(key_value) -> None:
        key, value = key_value
        path.write_text(json.dumps({**valid, key: value}))
        camera = path if role == "camera" else inputs["camera.json"]
        hints = path if role == "hints" else (inputs["hints.json"] if command != "navigate" else None)
        assert_refused(run_cli(_argv(command, inputs, camera, hints)), 2, key, check="bad_config")
        with pytest.raises(ConfigError, match=key):
            build({**valid, key: value})

    case()


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(("which", "name"), [("list.json", "JSON object"), ("bad.json", "not valid JSON"),
                                             ("dir", "directory"), ("missing", "missing"), ("moon.png", "JSON")])
def test_camera_and_hints_files_that_are_not_json_objects(command, which, name, inputs):
    for role in ("camera", "hints"):
        cam = inputs[which] if role == "camera" else inputs["camera.json"]
        hints = inputs[which] if role == "hints" else inputs["hints.json"]
        res = run_cli(_argv(command, inputs, cam, hints))
        assert_refused(res, 2, (role, str(inputs[which].name)), check="bad_config")


_ATTITUDES = st.one_of(
    _bad_vector(4).map(json.dumps),  # booleans, numeric strings, NaN, wrong length ...
    st.tuples(st.sampled_from([[1, 0, 0], [0, 1, 0], [0, 0, 1]]), st.sampled_from([True, "1", None, [1]]))
    .map(lambda t: json.dumps([t[0], [0, 1, 0], [0, 0, t[1]]])),
    st.sampled_from(['{"quaternion": [0, 0, 0, 1], "order": 5}', '{"foo": 1}', '{"C_ci": "eye"}', "[", "{}",
                     '[[1, 0], [0, 1]]', "[0, 0, 0, 2]", '{"q": [0, 0, 0, true]}']),
)


def test_hostile_attitude_exits_2_naming_it(inputs):
    @FUZZ
    @given(attitude=_ATTITUDES)
    def case(attitude: str) -> None:
        res = run_cli(["navigate", inputs["moon.png"], "--camera", inputs["camera.json"], "--epoch",
                       "2026-01-01T00:00:00Z", "--attitude", attitude, "--json"])
        obj = assert_refused(res, 2, ("attitude", "quaternion", "C_ci"))
        assert obj["check"] in ("bad_config", "bad_attitude")

    case()
