"""Cropped Moons (Aerospace 2015 §3.4): located to 0.2 px when enough lit limb is in the frame,
a typed :class:`~jaxlimb.errors.ArcTooShortError` when the Sun-facing side is outside it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxlimb.errors import ArcTooShortError, CheckFailed
from jaxlimb.pipeline import locate
from jaxlimb.pipeline.checks import MIN_LIT_ARC_DEG, arc_span_deg, check_lit_arc

from ._scenes import SMALL_CAMERA, errors, scene, sun_hints

#: Moon at 40 000 km on the 400x500 test camera: apparent radius ~61 px.
_RANGE_KM = 40000.0


def _hints(truth):
    # the range prior a navigation filter has, 5 % off
    return sun_hints(truth, range_prior_km=1.05 * truth.range_km)


@pytest.mark.parametrize(
    ("center_rc", "sun_angle_deg"),
    [
        ((25.0, 250.0), 270.0),   # centre inside the frame, cut by the top edge, Sun down (into the frame)
        ((-18.0, 240.0), 250.0),  # centre outside the frame (above it)
        ((200.0, 520.0), 160.0),  # centre outside the right edge, Sun toward the left and up
    ],
)
def test_cropped_moon_located_within_0p2_px(center_rc, sun_angle_deg):
    img, tr = scene(_RANGE_KM, 30.0, center_rc, sun_angle_deg=sun_angle_deg, psf=0.9, seed=3)
    assert tr.crop != "none"
    m = locate(img, SMALL_CAMERA, _hints(tr))
    dc, dr = errors(m, tr)
    assert dc <= 0.2, (dc, dr, m.extras["lit_arc_deg"])
    assert abs(dr) <= 0.2, (dc, dr, m.extras["lit_arc_deg"])
    assert m.extras["lit_arc_deg"] >= MIN_LIT_ARC_DEG


def test_sun_facing_side_outside_the_frame_is_arc_too_short():
    # centre above the frame, Sun up: only the terminator side of the Moon is in the frame
    img, tr = scene(_RANGE_KM, 30.0, (-18.0, 240.0), sun_angle_deg=80.0, psf=0.9, seed=3)
    with pytest.raises(ArcTooShortError) as ei:
        locate(img, SMALL_CAMERA, _hints(tr))
    assert isinstance(ei.value, CheckFailed) and ei.value.exit_code == 3
    assert ei.value.check == "arc_too_short"


def test_short_lit_arc_is_arc_too_short():
    # most of the Sun-facing limb is above the frame: a ~30-deg lit arc is left (centre sigma ~0.3 px)
    img, tr = scene(_RANGE_KM, 30.0, (-30.0, 250.0), sun_angle_deg=20.0, psf=0.9, seed=3)
    with pytest.raises(ArcTooShortError):
        locate(img, SMALL_CAMERA, _hints(tr))


def test_arc_span_and_check():
    a = np.radians(np.linspace(-20.0, 20.0, 50))
    assert arc_span_deg(a) == pytest.approx(40.0, abs=1e-9)
    assert arc_span_deg(a + math.pi) == pytest.approx(40.0, abs=1e-9)  # across the +-pi cut
    assert arc_span_deg(np.radians([0.0, 90.0, 180.0, 270.0])) == pytest.approx(270.0)
    with pytest.raises(ArcTooShortError):
        check_lit_arc(a)
    assert check_lit_arc(np.radians(np.linspace(-40.0, 40.0, 50))) == pytest.approx(80.0)
    # a lit-side window narrower than the limit (thin crescent, whole lit limb in the frame): 90 % of it
    assert check_lit_arc(a, halfangle=math.radians(21.0)) == pytest.approx(40.0)


def test_short_lit_arc_is_decided_before_the_circle_fit():
    """Benchmark row ``cropped`` 2 (independent renderer): 24-34 deg of lit limb in the frame, the front end's
    points on 17 deg of it and its circle 77 px for 54.  The annulus about that circle passed the lit-arc check
    and the circle sigmoid did not converge (``no_convergence``); the check on the front end's points decides it
    before any fit (``edge.check_front_end_arc``)."""
    from jaxlimb.imaging import Hints
    from jaxlimb.render.independent import MOON_FAMILIES, moon_case

    case = moon_case("cropped", np.random.default_rng([2026, 0, MOON_FAMILIES.index("cropped"), 2]))
    with pytest.raises(ArcTooShortError) as ei:
        locate(case.image, case.camera, Hints.from_dict(case.hints))
    assert "spans 11.9 deg" in str(ei.value)
