"""Christian-Robinson horizon navigation: exact recovery, covariance vs Monte Carlo, bad input."""

import numpy as np
import pytest

from jaxlimb.errors import AttitudeError, GeometryError
from jaxlimb.geometry import horizon as hz
from jaxlimb.geometry.attitude import rotation_vector_to_dcm
from jaxlimb.geometry.camera import Camera

MOON = 1737.4
EARTH = (6378.137, 6378.137, 6356.752)


def _look_at(p_body, tilt=(0.0, 0.0, 0.0)):
    """R_body_to_camera with the boresight near the body centre (then tilted by `tilt`, rad)."""
    z = -p_body / np.linalg.norm(p_body)
    x = np.cross([0.3, 0.1, 1.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return rotation_vector_to_dcm(tilt) @ np.stack([x, y, z])


def _sphere_cone_rays(u, D, R, n):
    """Rays on the cone of half-angle asin(R/D) around unit u (independent construction)."""
    a = np.arcsin(R / D)
    e1 = np.cross(u, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.cos(a) * u + np.sin(a) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)


@pytest.mark.parametrize("method", ["ls", "tls"])
def test_sphere_exact(method):
    p = np.array([2.0e4, -1.5e5, 9.0e4])  # camera rel. Moon, body frame
    R = _look_at(p, (0.01, -0.02, 0.4))
    c_cam = R @ (-p)
    D = np.linalg.norm(p)
    v = _sphere_cone_rays(c_cam / D, D, MOON, 40)
    sol = hz.horizon_navigation(v, MOON, R, method=method)
    assert np.linalg.norm(sol.r_camera_km - R @ p) / D < 1e-9
    assert abs(sol.range_km / D - 1) < 1e-10
    assert sol.rms_residual < 1e-12


@pytest.mark.parametrize("method", ["ls", "tls"])
@pytest.mark.parametrize("arc", [(0.0, 2 * np.pi), (0.3, 1.9)])
def test_oblate_spheroid_and_triaxial_exact(method, arc):
    for radii, p in ((EARTH, np.array([3.0e4, 1.0e4, 2.5e4])), ((252.1, 248.6, 246.3), np.array([900.0, -700.0, 400.0]))):
        R = _look_at(p, (0.05, 0.02, -1.0))
        v = hz.limb_directions(radii, p, R, 25, arc)
        # the rays are tangent: v^T M v = 0 for the cone of Mortari Eq. 2 in the camera frame
        J = np.diag(np.asarray(radii) ** -2.0)
        M = J @ np.outer(p, p) @ J - (p @ J @ p - 1) * J
        Mc = R @ M @ R.T
        assert np.max(np.abs(np.einsum("ij,jk,ik->i", v, Mc, v))) < 1e-14 * np.abs(Mc).max()
        sol = hz.horizon_navigation(v, radii, R, method=method)
        assert np.linalg.norm(sol.r_camera_km - R @ p) / np.linalg.norm(p) < 1e-9


def test_whitening_is_a_square_root():
    R = rotation_vector_to_dcm([0.3, -0.2, 0.9])
    B = hz.whitening(EARTH, R)
    np.testing.assert_allclose(B.T @ B, R @ np.diag(np.asarray(EARTH) ** -2.0) @ R.T, rtol=1e-12)
    assert np.allclose(np.tril(B, -1), 0.0)  # upper triangular = L^T


def test_ignoring_oblateness_is_biased():
    """Using a sphere model for the Earth gives a km-level error: the ellipsoid model matters."""
    p = np.array([3.0e4, 1.0e4, 2.5e4])
    R = _look_at(p)
    v = hz.limb_directions(EARTH, p, R, 60)
    err = np.linalg.norm(hz.horizon_navigation(v, 6371.0, R).r_camera_km - R @ p)
    assert err > 2.0  # 4.6 km at 40 000 km


@pytest.mark.parametrize("arc", [(0.0, 2 * np.pi), (0.0, np.pi / 2)])
def test_covariance_consistent_with_monte_carlo(arc):
    """Normalised error^2 mean ≈ 3 (600 trials: its standard error is ≈ 0.1)."""
    cam = Camera(k1=-0.02, k2=0.001)
    p = np.array([5.0e4, 3.0e4, 4.0e4])
    R = _look_at(p, (0.02, -0.03, 0.1))
    mc = hz.horizon_monte_carlo(cam, EARTH, p, R, n_points=80, sigma_px=0.3, n_trials=600, seed=5, arc=arc)
    assert 2.6 < mc.mean_nees < 3.4, mc.mean_nees
    np.testing.assert_allclose(mc.rms_error_km, mc.predicted_sigma_km, rtol=0.15)
    assert np.all(np.abs(mc.bias_km) < 4 * mc.predicted_sigma_km / np.sqrt(600))


def test_pixels_noise_free_with_distortion():
    cam = Camera(k1=-0.05, p1=2e-4)
    p = np.array([1.0e4, -6.0e4, 2.0e4])
    R = _look_at(p, (0.01, 0.04, 0.0))
    rc = cam.project(hz.limb_directions(MOON, p, R, 30))
    sol = hz.horizon_from_pixels(cam, rc, MOON, R, sigma_px=0.2)
    assert np.linalg.norm(sol.r_camera_km - R @ p) / np.linalg.norm(p) < 1e-9
    assert sol.covariance_km2.shape == (3, 3) and np.all(np.linalg.eigvalsh(sol.covariance_km2) > 0)


def test_bad_inputs():
    p = np.array([0.0, 0.0, 1.0e4])
    R = _look_at(p)
    v = hz.limb_directions(MOON, p, R, 10)
    with pytest.raises(GeometryError, match="outside the ellipsoid"):
        hz.limb_directions(MOON, [0.0, 0.0, 1000.0], R, 10)
    with pytest.raises(GeometryError, match="radii"):
        hz.horizon_navigation(v, (1737.4, 0.0, 1737.4), R)
    with pytest.raises(GeometryError, match="radii"):
        hz.horizon_navigation(v, (1737.4, np.nan, 1737.4), R)
    with pytest.raises(AttitudeError, match="R_body_to_camera"):
        hz.horizon_navigation(v, MOON, R * 1.01)
    with pytest.raises(GeometryError, match="at least 3"):
        hz.horizon_navigation(v[:2], MOON, R)
    with pytest.raises(GeometryError, match="degenerate"):
        hz.horizon_navigation(np.repeat(v[:1], 5, axis=0), MOON, R)
    # points all around the sphere of directions are no limb: n = 0
    six = np.vstack([np.eye(3), -np.eye(3)])
    with pytest.raises(GeometryError, match=r"n\^T n"):
        hz.horizon_navigation(six, 1.0, np.eye(3))
    with pytest.raises(GeometryError, match="method"):
        hz.horizon_navigation(v, MOON, R, method="svd")
