"""The §3 prior: hints parsing, expected radius, illumination cases, derived settings, Check 1."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from jaxlimb.errors import ConfigError, TooBigError, TooSmallError, TooThinError
from jaxlimb.geometry.camera import Camera
from jaxlimb.imaging import (
    Hints,
    Prior,
    PriorOptions,
    check_prior,
    derived_settings,
    detect_body,
    illumination_parameter,
    prior_from_hints,
    prior_from_image,
    ransac_tests,
    sun_direction_image,
)

from ._synth import render_disk, sun_vector


def test_hints_from_dict_ignores_unknown_and_normalises(tmp_path):
    d = {"body": " Moon ", "sun_dir_camera": [0, 0, -2], "expected_radius_px": 120, "whatever": 5, "bit_depth": 12}
    h = Hints.from_dict(d)
    assert h.body == "moon" and h.sun_dir_camera == (0.0, 0.0, -1.0) and h.expected_radius_px == 120.0
    p = tmp_path / "h.json"
    p.write_text(json.dumps(d))
    assert Hints.from_json(p) == h
    assert Hints.from_dict({}).radius_km() is None
    assert Hints(body="moon").radius_km() == pytest.approx(1737.4)
    assert Hints(body="earth", atmosphere_km=100).radius_km() == pytest.approx((2 * 6378.137 + 6356.752) / 3 + 100)


@pytest.mark.parametrize(
    "key, value",
    [
        ("body", ""),
        ("body", 3),
        ("body_radii_km", [1, 2]),
        ("body_radii_km", [1, -2, 3]),
        ("expected_radius_px", -1),
        ("expected_radius_px", "big"),
        ("expected_radius_px", True),
        ("expected_radius_uncertainty_frac", 0),
        ("range_prior_km", float("inf")),
        ("sun_dir_camera", [0, 0, 0]),
        ("sun_dir_camera", [1, 2]),
        ("atmosphere_km", -5),
        ("bit_depth", 40),
        ("bit_depth", 8.5),
        ("R_body_to_camera", [[1, 0, 0], [0, 1, 0], [0, 0, 2]]),
        ("R_body_to_camera", [[1, 0, 0], [0, 1, 0], [0, 0, -1]]),
        ("R_body_to_camera", [[1, 0], [0, 1]]),
    ],
)
def test_hints_bad_values_name_the_key(key, value):
    with pytest.raises(ConfigError, match=key):
        Hints.from_dict({key: value})


def test_hints_bad_json(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(ConfigError, match="not valid JSON"):
        Hints.from_json(p)
    with pytest.raises(ConfigError, match="does not exist"):
        Hints.from_json(tmp_path / "missing.json")
    with pytest.raises(ConfigError, match="JSON object"):
        Hints.from_dict([1, 2])


def test_expected_radius_eq1_matches_camera():
    cam = Camera.default()
    h = Hints(body="moon", range_prior_km=384400.0)
    p = prior_from_hints(h, cam)
    assert p is not None
    assert p.expected_radius_px == pytest.approx(cam.radius_px(1737.4, 384400.0), rel=1e-12)
    assert p.case == "unknown" and p.illumination_px == pytest.approx(2 * p.expected_radius_px)
    assert prior_from_hints(Hints(body="moon"), cam) is None


def test_illumination_cases():
    Rm, ro = 1737.4, 100000.0
    pr = 100.0
    assert illumination_parameter(pr, 0.0, ro, Rm) == (2 * pr, "full")
    # close to the body, theta > pi/2 with |r_o| < r_cr: new
    assert illumination_parameter(pr, math.radians(179.5), 1800.0, Rm)[1] == "new"
    pi_g, case_g = illumination_parameter(pr, math.radians(60), ro, Rm)
    pi_c, case_c = illumination_parameter(pr, math.radians(120), ro, Rm)
    assert case_g == "gibbous" and case_c == "crescent"
    # far field -> p_r (1 + cos theta) (Eq. 10 and 14)
    assert pi_g == pytest.approx(pr * 1.5, rel=0.03)
    assert pi_c == pytest.approx(pr * 0.5, rel=0.05)
    far_g, _ = illumination_parameter(pr, math.radians(60), 1e9, Rm)
    assert far_g == pytest.approx(1.5 * pr, rel=1e-5)
    assert illumination_parameter(pr, math.radians(60))[0] == pytest.approx(1.5 * pr)
    with pytest.raises(ConfigError):
        illumination_parameter(pr, 4.0)


def test_prior_from_hints_with_sun_and_checks():
    cam = Camera.default()
    s = sun_vector(120.0, (1.0, 0.0))  # Sun toward +row in the image, phase 120 deg
    p = prior_from_hints(Hints(body="moon", range_prior_km=60000.0, sun_dir_camera=tuple(s)), cam)
    assert p.case == "crescent" and p.phase_rad == pytest.approx(math.radians(120.0))
    assert p.sun_dir_rc == pytest.approx((1.0, 0.0), abs=1e-12)
    assert 0.4 * p.expected_radius_px < p.illumination_px < 0.6 * p.expected_radius_px
    with pytest.raises(TooThinError, match="p_i"):
        prior_from_hints(Hints(body="moon", range_prior_km=60000.0, sun_dir_camera=(0.0, 0.001, 1.0)), cam)
    with pytest.raises(TooSmallError, match="min_diameter_px"):
        prior_from_hints(Hints(expected_radius_px=3.0), cam)
    with pytest.raises(TooBigError, match="fills"):
        prior_from_hints(Hints(expected_radius_px=5000.0), cam)


def test_sun_direction_image_projection():
    assert sun_direction_image((1.0, 0.0, 0.0)) == pytest.approx((0.0, 1.0))
    assert sun_direction_image((0.0, -1.0, 0.5)) == pytest.approx((-1.0, 0.0))
    assert sun_direction_image((0.0, 0.0, -1.0)) is None
    cam = Camera(focal_length_mm=16.0, pixel_pitch_mm=0.0022, rows=1944, cols=2592)
    c = (100.0, 300.0)  # far off-axis body
    s = np.array([0.3, -0.5, 0.4])
    s /= np.linalg.norm(s)
    d = sun_direction_image(s, cam, c)
    u = cam.los(np.array(c))
    q = cam.project(u * 1e4 + s * 1.0) - cam.project(u * 1e4)
    q /= np.linalg.norm(q)
    assert np.allclose(d, q, atol=1e-6)


def test_derived_settings_eq15_17():
    full = Prior(150.0, 0.1, 300.0, 0.0, "full")
    st = derived_settings(full)
    assert st.n_points == 1500  # 4 pi 150 = 1885 capped at 1500
    assert st.box_size == 21 and st.ransac_dmax == pytest.approx(7.5)
    thin = Prior(150.0, 0.1, 10.0, 2.5, "crescent")
    st = derived_settings(thin)
    assert st.n_points == math.ceil(2 * math.pi * 150)
    small = Prior(10.0, 0.1, 20.0, 0.0, "full")
    st = derived_settings(small)
    assert st.box_size == 9 and st.box_size % 2 == 1 and st.ransac_dmax == 2.0
    assert ransac_tests(10) == 24 and ransac_tests(1000) == 500 and ransac_tests(3) == 1
    st = derived_settings(Prior(40.0, 0.1, 80.0), PriorOptions(box_factor=0.1))
    assert st.box_size == 5


def test_check_prior_and_options_validation():
    check_prior(Prior(100.0, 0.1, 50.0), (500, 500))
    with pytest.raises(TooBigError):
        check_prior(Prior(400.0, 0.1, 50.0), (500, 500))
    with pytest.raises(ConfigError):
        PriorOptions(min_points=1)
    with pytest.raises(ConfigError):
        PriorOptions(box_factor=-1.0)


@pytest.mark.parametrize("phase, lo, hi", [(0.0, 0.0, 0.35), (60.0, 0.5, 1.6), (120.0, 1.5, 2.6)])
def test_prior_from_image(phase, lo, hi):
    img = render_disk((300, 300), (150.0, 150.0), 100.0, phase_deg=phase, sun_dir_rc=(0.0, 1.0), blur_sigma=1.0, noise_sigma=2.0, ss=3)
    p = prior_from_image(img)
    assert p.source == "image"
    assert p.expected_radius_px == pytest.approx(100.0, rel=0.05)
    assert lo <= p.phase_rad <= hi
    reg = detect_body(img)
    assert reg.roi[0] <= 50 and reg.roi[1] >= 250 and reg.roi[3] >= 250


def test_image_prior_radius_band_open_when_cropped():
    full = prior_from_image(render_disk((300, 300), (150.0, 150.0), 100.0, blur_sigma=1.0, ss=2))
    lo, hi = full.radius_range
    assert lo < 100.0 < hi and math.isfinite(hi) and hi < 170.0
    cut = prior_from_image(render_disk((300, 300), (150.0, -40.0), 100.0, blur_sigma=1.0, ss=2))
    lo, hi = cut.radius_range
    assert math.isinf(hi) and lo < 100.0
