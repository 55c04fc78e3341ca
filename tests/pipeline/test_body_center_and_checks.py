"""The body-centre correction at the frame corner, and the checks 1-5 as typed errors through ``locate``."""

from __future__ import annotations

import numpy as np
import pytest

from jaxlimb.errors import (
    ConfigError,
    ConvergenceError,
    ImageContentError,
    JumpError,
    NoBodyError,
    RadiusInconsistentError,
    TooBigError,
    TooManyOutliersError,
    TooSmallError,
    TooThinError,
)
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.hints import Hints
from jaxlimb.pipeline import locate
from jaxlimb.pipeline.options import LocateOptions

from ._scenes import SMALL_CAMERA, scene, sun_hints


def test_body_center_correction_at_the_frame_corner():
    """Moon at 60 000 km near the corner of the default 1944x2592 imager (12 deg off-axis).

    The limb is an ellipse whose centre is ~1 px from the image of the body centre; the
    circle fit finds the ellipse centre, the sphere-constrained ESF + exact inverse the
    body centre.
    """
    cam = Camera.default()
    img, tr = scene(60000.0, 0.0, (1944.0 - 235.0, 2592.0 - 235.0), 30.0, "lunar-lambert", camera=cam)
    assert tr.crop == "none"
    m = locate(img, cam, sun_hints(tr))
    err = np.hypot(*np.subtract(m.center_rc, tr.center_rc))
    naive = np.hypot(*np.subtract(m.extras["circle_fit"]["center_rc"], tr.center_rc))
    offset = np.hypot(*np.subtract(tr.limb.center_rc, tr.center_rc))
    assert offset > 0.9  # the geometry: ellipse centre vs image of the centre
    assert naive > 0.8  # the circle centre carries that offset
    assert err <= 0.05, (err, naive)
    # the equivalent radius f tan(alpha) and the range follow from the apparent size
    assert m.radius_px == pytest.approx(tr.apparent_radius_px, abs=0.2)  # + the limb's rim bias (~0.1 px)
    assert m.range_km == pytest.approx(tr.range_km, rel=1e-3)
    assert np.degrees(np.arccos(np.clip(np.dot(m.los_camera, tr.los_cam), -1, 1))) * 3600 < 2.0  # arcsec
    ell = m.extras["limb_ellipse"]
    assert np.hypot(*np.subtract(ell["center_rc"], tr.limb.center_rc)) <= 0.05


def test_body_center_correction_with_the_physical_profile():
    cam = Camera.default()
    img, tr = scene(60000.0, 45.0, (1944.0 - 235.0, 2592.0 - 235.0), 30.0, "lunar-lambert", camera=cam)
    m = locate(img, cam, sun_hints(tr), LocateOptions(profile="lunar-lambert"))
    assert np.hypot(*np.subtract(m.center_rc, tr.center_rc)) <= 0.05
    assert abs(m.radius_px - tr.apparent_radius_px) <= 0.05
    assert m.range_km == pytest.approx(tr.range_km, rel=3e-4)
    with pytest.raises(ConfigError):  # the profile needs the Sun direction
        locate(img, cam, Hints(body="moon"), LocateOptions(profile="lunar-lambert"))


def test_no_camera_reports_the_circle_center():
    img, tr = scene(30000.0, 0.0, (200.0, 250.0), 30.0, "uniform")
    m = locate(img)
    assert m.center_rc == tuple(m.extras["circle_fit"]["center_rc"])
    assert "limb_ellipse" not in m.extras


@pytest.mark.parametrize("fill", [0.0, 255.0])
def test_constant_frames_have_no_body(fill):
    with pytest.raises(NoBodyError):
        locate(np.full((200, 300), fill))


def test_pure_noise_has_no_body():
    rng = np.random.default_rng(3)
    with pytest.raises(NoBodyError):
        locate(rng.integers(0, 256, (300, 400)).astype(np.uint8))


def test_bad_arrays_are_input_errors():
    for bad in (np.zeros((1, 1)), np.zeros((0, 5)), np.full((20, 20), np.nan), np.zeros((4, 4, 4, 4))):
        with pytest.raises(ImageContentError):
            locate(bad)


def test_check1_too_small_and_too_big():
    img, _ = scene(1737.4 * 1403.0 / 1.0, 0.0, (200.0, 250.0))  # ~1 px radius: a 2-px body
    with pytest.raises((TooSmallError, NoBodyError)):
        locate(img)
    img, _ = scene(7000.0, 0.0, (200.0, 250.0))  # radius 360 px: fills the 400x500 frame
    with pytest.raises(TooBigError):
        locate(img)
    img, _ = scene(30000.0, 0.0, (200.0, 250.0))
    with pytest.raises(TooBigError):  # the prior says so first (Check 1 runs before the search)
        locate(img, None, Hints(body="moon", expected_radius_px=400.0))
    with pytest.raises(TooSmallError):
        locate(img, SMALL_CAMERA, Hints(body="moon", range_prior_km=2.0e6))


def test_check2_too_thin():
    img, tr = scene(30000.0, 170.0, (200.0, 250.0))
    with pytest.raises(TooThinError):
        locate(img)
    with pytest.raises(TooThinError):
        locate(img, SMALL_CAMERA, sun_hints(tr, range_prior_km=30000.0))


def test_check3_too_many_outliers():
    # a bright square: the gradient front end finds "a circle" through its corners, but the
    # sigmoid residuals along the straight sides are far off
    rng = np.random.default_rng(0)
    a = np.zeros((400, 500))
    a[100:300, 150:350] = 200.0
    a += rng.normal(0.0, 2.0, a.shape)
    with pytest.raises(TooManyOutliersError):
        locate(a)


def test_check4_radius_inconsistent_with_prior():
    img, _ = scene(30000.0, 0.0, (200.0, 250.0))  # radius 81 px
    with pytest.raises(RadiusInconsistentError):
        locate(img, None, Hints(body="moon", expected_radius_px=40.0, expected_radius_uncertainty_frac=0.05))


def test_check5_no_convergence_and_jump(monkeypatch):
    from jaxlimb.pipeline.sphere import edge

    img, _ = scene(30000.0, 0.0, (200.0, 250.0))
    with pytest.raises(ConvergenceError):
        locate(img, options=LocateOptions(max_steps=1))
    with monkeypatch.context() as mp:
        mp.setattr(edge, "jump_threshold", lambda dr: 1e-4)  # a limit no fit meets
        with pytest.raises(JumpError):
            locate(img)
    m = locate(img)
    assert m.extras["jump_px"] <= m.extras["jump_limit_px"]
