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


def test_albedo_field_bound_is_the_white_bound_without_albedo_and_the_dense_one_with_it():
    """``tau = 0`` gives :func:`crlb`'s bound; with an albedo field the Woodbury form equals
    ``(J^T Sigma^-1 J)^-1`` with ``Sigma = D + K C K^T`` formed densely, and the centre's bound grows with ``tau``."""
    import math

    import jax.numpy as jnp

    from jaxlimb.analysis.crlb import albedo_field_crlb
    from jaxlimb.models import LIMB_PROFILE, PROFILE_FIXED, LimbProfileParams
    from jaxlimb.models.profile_columns import albedo_field_columns, albedo_nodes, albedo_prior

    p = LimbProfileParams(r0=100.0, c0=110.0, a=30.0, theta=0.0, rho=1.0, sigma=0.9, amp=1000.0, ymin=5.0, sun_r=0.6,
                          sun_c=0.8, phase=0.8, inv_f=1e-4, L=0.5, L_slope=-1.0, L_ref=0.6)
    ang = np.linspace(0.0, 2.0 * math.pi, 90, endpoint=False)
    g = np.stack(np.meshgrid(ang, np.linspace(25.0, 35.0, 5)), -1).reshape(-1, 2)
    rc = np.column_stack([100.0 + g[:, 1] * np.sin(g[:, 0]), 110.0 + g[:, 1] * np.cos(g[:, 0])])
    var = np.full(len(rc), 900.0)
    white = crlb(LIMB_PROFILE, rc, p, 30.0, fixed=PROFILE_FIXED)
    none = albedo_field_crlb(rc, p, var, 0.0, 0.2)
    np.testing.assert_allclose(none.covariance, white.covariance, rtol=1e-9)
    ell = math.radians(20.0)
    field = albedo_field_crlb(rc, p, var, 0.15, ell)
    theta, n_psi = albedo_nodes(p, rc, ell)
    K = np.asarray(albedo_field_columns(p, jnp.asarray(rc), jnp.asarray(theta), jnp.zeros(n_psi)))
    J = np.asarray(LIMB_PROFILE.jacobian(p, jnp.asarray(rc)))[:, list(LIMB_PROFILE.free_indices(PROFILE_FIXED))]
    S = np.diag(var) + K @ albedo_prior(theta, n_psi, 0.15, ell) @ K.T
    np.testing.assert_allclose(field.covariance, np.linalg.inv(J.T @ np.linalg.solve(S, J)), rtol=1e-6)
    small = albedo_field_crlb(rc, p, var, 0.05, ell)
    assert white.std["r0"] < small.std["r0"] < field.std["r0"]
    with pytest.raises(LimbInputError):
        albedo_field_crlb(rc, p, var, -0.1, ell)
