"""Tests of the CRLB extensions: delta method, LOS/range bound (jaxlimb.analysis.crlb)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxlimb.analysis.crlb import crlb, crlb_los_range, delta_method, los_range_bound, numerical_jacobian
from jaxlimb.analysis.error_propagation import range_sigma_from_radius_sigma
from jaxlimb.errors import LimbInputError
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.navigation import sphere_from_circle
from jaxlimb.models import CIRCLE, CircleParams

MOON_KM = 1737.4


def test_delta_method_linear_map_is_exact(rng):
    a = rng.standard_normal((4, 4))
    cov = a @ a.T
    g = rng.standard_normal((2, 4))
    np.testing.assert_allclose(delta_method(cov, g), g @ cov @ g.T, rtol=1e-12)
    # scalar g: (p,) jacobian -> (1, 1)
    assert delta_method(cov, g[0]).shape == (1, 1)
    with pytest.raises(LimbInputError, match="columns"):
        delta_method(cov, np.ones((2, 3)))
    with pytest.raises(LimbInputError, match="square"):
        delta_method(np.ones((2, 3)), np.ones((2, 3)))


def test_numerical_jacobian_matches_analytic():
    fn = lambda x: np.array([np.sin(x[0]) * x[1], x[1] ** 3])  # noqa: E731
    x = np.array([0.3, 1.7])
    want = np.array([[np.cos(0.3) * 1.7, np.sin(0.3)], [0.0, 3 * 1.7**2]])
    np.testing.assert_allclose(numerical_jacobian(fn, x, 1e-5), want, rtol=1e-8)


def test_range_bound_on_boresight_is_eq38():
    cam = Camera()
    D = 150_000.0
    r = cam.radius_px(MOON_KM, D)
    sr = 0.05
    cov = np.diag([0.02**2, 0.02**2, sr**2])
    b = los_range_bound(cam, cam.principal_point_rc, r, cov, MOON_KM)
    assert b.range_km == pytest.approx(D, rel=1e-9)
    assert b.sigma_range_km == pytest.approx(float(range_sigma_from_radius_sigma(D, sr, cam, MOON_KM)), rel=1e-5)
    # LOS: a centre error of 0.02 px per axis is 0.02/f rad per axis
    # (to O(sin^2 alpha) ~ 1e-4: the limb-circle centre is not exactly the image of the body centre)
    assert b.sigma_los_rad == pytest.approx(np.sqrt(2) * 0.02 / cam.focal_px, rel=1e-3)
    assert set(b.as_dict()) >= {"los_camera", "range_km", "sigma_range_km", "sigma_los_arcsec"}


def test_delta_method_agrees_with_monte_carlo_off_axis(rng):
    cam = Camera()
    center = (300.0, 500.0)  # far off-axis: the exact (not Eq. 36) geometry matters
    r, cov = 120.0, np.array([[4e-4, 1e-4, 0.0], [1e-4, 3e-4, 5e-5], [0.0, 5e-5, 2e-4]])
    b = los_range_bound(cam, center, r, cov, MOON_KM)
    x = rng.multivariate_normal([center[0], center[1], r], cov, size=2000)
    out = np.array([np.append(*sphere_from_circle(cam, (xi[0], xi[1]), xi[2], MOON_KM)) for xi in x])
    emp = np.cov(out, rowvar=False)
    assert np.sqrt(emp[3, 3]) == pytest.approx(b.sigma_range_km, rel=0.08)
    np.testing.assert_allclose(np.sqrt(np.diag(emp)[:3]), np.sqrt(np.diag(b.covariance)[:3]), rtol=0.08, atol=1e-12)


def test_crlb_los_range_from_model_bound():
    truth = CircleParams(200.3, 201.1, 150.0, 3.0, 200.0, 20.0)
    rr, cc = np.mgrid[40:362, 40:362]
    rc = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
    d = np.hypot(rc[:, 0] - 200.3, rc[:, 1] - 201.1)
    rc = rc[np.abs(d - 150.0) < 5]
    bound = crlb(CIRCLE, rc, truth, 10.0)
    cam = Camera(rows=401, cols=401, focal_length_mm=16.0)
    b = crlb_los_range(bound, truth, cam, MOON_KM)
    sr = bound.std["radius"]
    D = cam.range_from_radius(150.0, MOON_KM)
    assert b.sigma_range_km == pytest.approx(float(range_sigma_from_radius_sigma(D, sr, cam, MOON_KM)), rel=0.02)
    with pytest.raises(LimbInputError, match="radius"):
        crlb_los_range(crlb(CIRCLE, rc, truth, 10.0, fixed=("radius",)), truth, cam, MOON_KM)
