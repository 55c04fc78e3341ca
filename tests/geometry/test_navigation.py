"""Observer position r_o = r_m - C_ci^T r_om and its linear covariance vs Monte Carlo."""

import numpy as np
import pytest

from jaxlimb.errors import AttitudeError, GeometryError
from jaxlimb.geometry.attitude import quat_to_dcm, rotation_vector_to_dcm
from jaxlimb.geometry.camera import Camera, sphere_image_ellipse
from jaxlimb.geometry.navigation import (
    monte_carlo_navigation,
    navigate,
    navigate_from_circle,
    observer_position,
    sphere_from_circle,
    sphere_from_ellipse,
    tangent_basis,
)


def _attitude(rng):
    q = rng.normal(size=4)
    return quat_to_dcm(q / np.linalg.norm(q))


def test_observer_position_roundtrip(rng):
    C = _attitude(rng)
    r_m = np.array([3.0e5, -1.2e5, 4.0e4])
    r_o = np.array([1.0e4, 2.0e4, -3.0e3])
    r_om_cam = C @ (r_m - r_o)
    D = np.linalg.norm(r_om_cam)
    est = observer_position(r_m, C, 7.0 * r_om_cam / D, D)  # LOS need not be unit
    np.testing.assert_allclose(est, r_o, rtol=0, atol=1e-8)


def test_bad_inputs():
    C = np.eye(3)
    with pytest.raises(GeometryError, match="range_km"):
        observer_position(np.zeros(3), C, [0, 0, 1], -5.0)
    with pytest.raises(GeometryError, match="los_camera"):
        observer_position(np.zeros(3), C, [0, 0, 0], 5.0)
    with pytest.raises(AttitudeError, match="orthonormal"):
        observer_position(np.zeros(3), np.diag([1.0, 1.0, 1.1]), [0, 0, 1], 5.0)
    with pytest.raises(AttitudeError, match="det"):
        observer_position(np.zeros(3), np.diag([1.0, 1.0, -1.0]), [0, 0, 1], 5.0)
    with pytest.raises(GeometryError, match="not both"):
        navigate(np.zeros(3), C, [0, 0, 1], 5.0, los_cov_rad2=np.eye(2), los_cov_px2=np.eye(2))


def _nees(samples, mean, P):
    d = samples - mean
    return np.einsum("ij,ij->i", d, np.linalg.solve(P, d.T).T)


@pytest.mark.parametrize("mode", ["px", "rad"])
def test_covariance_matches_monte_carlo(rng, mode):
    """All four error sources on; MC covariance within 10 % (Frobenius) and NEES mean ≈ 3."""
    cam = Camera(k1=-0.05, p2=1e-4)  # distortion on: the pixel Jacobian goes through it
    C = _attitude(rng)
    r_m = np.array([-2.1e5, 3.0e5, 1.1e5])
    rc = np.array([400.0, 2000.0])  # off-axis centre
    u = cam.los(rc)
    D = 150_000.0
    kw = dict(
        sigma_range_km=40.0,
        attitude_cov_rad2=np.diag([3e-5, 1e-5, 2e-5]) ** 2,
        body_cov_km2=np.diag([1.0, 2.0, 0.5]) ** 2,
    )
    if mode == "px":
        kw.update(los_cov_px2=np.array([[0.09, 0.02], [0.02, 0.04]]), camera=cam)
    else:
        kw.update(los_cov_rad2=np.array([[4e-10, -1e-10], [-1e-10, 9e-10]]))
    sol = navigate(r_m, C, u, D, **kw)
    samples = monte_carlo_navigation(r_m, C, u, D, n_trials=4000, seed=7, **kw)
    P_mc = np.cov(samples.T)
    rel = np.linalg.norm(P_mc - sol.covariance_km2) / np.linalg.norm(sol.covariance_km2)
    assert rel < 0.1, rel
    np.testing.assert_allclose(samples.mean(axis=0), sol.position_km, atol=5 * np.max(sol.sigma_km) / np.sqrt(4000))
    nees = _nees(samples, sol.position_km, sol.covariance_km2)
    assert 2.8 < nees.mean() < 3.2, nees.mean()
    # contributions add up and each one is non-trivial
    total = sum(sol.contributions_km2.values())
    np.testing.assert_allclose(total, sol.covariance_km2, rtol=1e-12, atol=1e-12)
    for k, Pk in sol.contributions_km2.items():
        assert np.trace(Pk) > 0, k


def test_range_only_is_along_los(rng):
    """Range error alone: covariance is rank one along the inertial LOS with variance sigma_D^2."""
    C = _attitude(rng)
    u = np.array([0.1, -0.2, 1.0])
    u /= np.linalg.norm(u)
    sol = navigate(np.zeros(3), C, u, 1e5, sigma_range_km=25.0)
    ui = C.T @ u
    np.testing.assert_allclose(sol.covariance_km2, 625.0 * np.outer(ui, ui), atol=1e-9)


def test_attitude_error_is_perpendicular_and_scales_with_range(rng):
    """Isotropic attitude error s: the position error is D*s in the two directions ⟂ LOS, 0 along it."""
    C = _attitude(rng)
    u = np.array([0.0, 0.0, 1.0])
    D, s = 3.0e5, 1e-5
    sol = navigate(np.zeros(3), C, u, D, attitude_cov_rad2=s)
    ev = np.sort(np.linalg.eigvalsh(sol.covariance_km2))
    np.testing.assert_allclose(ev, [0.0, (D * s) ** 2, (D * s) ** 2], atol=1e-9)


def test_tangent_basis_orthonormal(rng):
    for _ in range(20):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        e1, e2 = tangent_basis(u)
        M = np.stack([u, e1, e2])
        np.testing.assert_allclose(M @ M.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(M) > 0


# ----------------------------------------------------------------------------- sphere image -> LOS, range


@pytest.mark.parametrize("D", [5.0e4, 3.844e5])
@pytest.mark.parametrize("rc", [(971.5, 1295.5), (150.0, 2450.0), (10.0, 10.0)])
def test_sphere_from_ellipse_and_circle_exact(D, rc):
    cam = Camera()
    u = cam.los(np.array(rc))
    el = sphere_image_ellipse(cam, D * u, 1737.4)
    a, b = el["semi_axes_px"]
    u1, D1 = sphere_from_ellipse(cam, el["center_rc"], (a, b), 1737.4)
    u2, D2 = sphere_from_circle(cam, el["center_rc"], 0.5 * (a + b), 1737.4)
    for uu, DD in ((u1, D1), (u2, D2)):
        assert np.max(np.abs(uu - u)) < 1e-10
        assert abs(DD / D - 1) < 1e-10
    if rc == (10.0, 10.0):  # image corner: the naive on-axis formula is 3.5 % short
        assert 1 - cam.range_from_radius(0.5 * (a + b), 1737.4) / D > 0.03


@pytest.mark.parametrize("rc", [(971.5, 1295.5), (150.0, 2450.0), (10.0, 10.0)])
def test_image_mean_radius_is_the_ellipses(rc):
    from jaxlimb.geometry.sphere_image import image_mean_radius, sphere_from_circle_fit

    cam = Camera()
    D = 3.844e5
    el = sphere_image_ellipse(cam, D * cam.los(np.array(rc)), 1737.4)
    a, b = el["semi_axes_px"]
    f_tan = cam.focal_px * np.tan(np.arcsin(1737.4 / D))
    mean = image_mean_radius(cam.focal_px, cam.principal_point_rc, el["center_rc"], f_tan)
    assert mean == pytest.approx(0.5 * (a + b), rel=1e-10)
    back = sphere_from_circle_fit(cam.focal_px, cam.principal_point_rc, el["center_rc"], mean)
    assert back.radius_equivalent_px == pytest.approx(f_tan, rel=1e-10)


def test_navigate_from_circle_covariance_vs_monte_carlo(rng):
    cam = Camera()
    C = _attitude(rng)
    r_m = np.array([1.0e5, -2.0e5, 3.0e4])
    rc, rad = np.array([300.0, 2200.0]), 80.0
    Pf = np.array([[0.04, 0.01, 0.005], [0.01, 0.09, -0.01], [0.005, -0.01, 0.0225]])
    sol = navigate_from_circle(r_m, C, cam, rc, rad, 1737.4, fit_cov_px2=Pf, attitude_cov_rad2=1e-5)
    L = np.linalg.cholesky(Pf)
    draws = rng.standard_normal((3000, 3)) @ L.T
    out = np.empty((3000, 3))
    for k, d in enumerate(draws):
        u, D = sphere_from_circle(cam, rc + d[:2], rad + d[2], 1737.4)
        Ck = rotation_vector_to_dcm(1e-5 * rng.standard_normal(3)) @ C
        out[k] = observer_position(r_m, Ck, u, D)
    P_mc = np.cov(out.T)
    assert np.linalg.norm(P_mc - sol.covariance_km2) / np.linalg.norm(sol.covariance_km2) < 0.1
    nees = _nees(out, sol.position_km, sol.covariance_km2)
    assert 2.8 < nees.mean() < 3.2


def test_sphere_from_image_refuses_distortion():
    with pytest.raises(GeometryError, match="undistort"):
        sphere_from_circle(Camera(k1=-0.1), (100.0, 100.0), 50.0, 1737.4)
    with pytest.raises(GeometryError, match="semi_axes_px"):
        sphere_from_ellipse(Camera(), (100.0, 100.0), (10.0, 20.0), 1737.4)
