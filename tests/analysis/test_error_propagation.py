"""Eq. 36-39 of the Aerospace 2015 paper vs Monte Carlo; the paper's slips shown by tests."""

import numpy as np
import pytest

from jaxlimb.analysis import error_propagation as ep
from jaxlimb.errors import GeometryError
from jaxlimb.geometry.attitude import attitude_error_vector, quat_to_dcm
from jaxlimb.geometry.camera import Camera


def test_eq36_matches_camera_and_inverse():
    cam = Camera()
    D = np.array([5e4, 1.5e5, 3.844e5])
    r = ep.radius_px(D, cam)
    np.testing.assert_allclose(r, [cam.radius_px(1737.4, d) for d in D], rtol=1e-13)
    np.testing.assert_allclose(ep.range_from_radius(r, cam), D, rtol=1e-12)


def test_eq37_is_the_derivative_and_eq38_its_inverse():
    D, h = 1.5e5, 1.0
    num = abs(ep.radius_px(D + h) - ep.radius_px(D - h)) / (2 * h)
    np.testing.assert_allclose(ep.radius_sigma_from_range_sigma(D, 1.0), num, rtol=1e-8)
    np.testing.assert_allclose(ep.range_sigma_from_radius_sigma(D, ep.radius_sigma_from_range_sigma(D, 7.0)), 7.0, rtol=1e-13)


@pytest.mark.parametrize("D", ep.FIG18_DISTANCES_KM)
def test_figure18_against_monte_carlo(D):
    """Fig. 18 data (Eq. 38) vs a Monte Carlo of the exact inverse of Eq. 36, small sigma_r."""
    fig = ep.figure18_data(sigma_r_px=[0.05, 0.2], distances_km=[D])
    for j, s in enumerate(fig.sigma_r_px):
        mc = ep.monte_carlo_range_sigma(D, s, n_trials=20_000, seed=1 + j)
        # 20 000 samples: std known to ~0.5 %
        assert abs(mc.std_km / fig.sigma_D_km[0, j] - 1) < 0.02
        assert abs(mc.bias_km) < 4 * mc.std_km / np.sqrt(mc.n_trials) + D * (s / fig.radius_px[0]) ** 2


def test_figure18_shape_and_scaling():
    fig = ep.figure18_data()
    assert fig.sigma_D_km.shape == (4, 21)
    np.testing.assert_allclose(fig.distances_km, [5e4, 1.5e5, 2.5e5, 3.5e5])
    # linear in sigma_r, roughly quadratic in D (D^2 / (f R) for D >> R)
    np.testing.assert_allclose(fig.sigma_D_km[:, 10] * 2, fig.sigma_D_km[:, 20], rtol=1e-12)
    ratio = fig.sigma_D_km[3, 20] / fig.sigma_D_km[0, 20]
    assert abs(ratio / 49.0 - 1) < 0.01
    # 0.1 px at 350 000 km is ~1000 km of range error on the 16 mm camera
    assert 900 < ep.range_sigma_from_radius_sigma(3.5e5, 0.1) < 1000


def test_eq38_first_order_breaks_down_for_large_relative_radius_error():
    """At 350 000 km r ≈ 36 px; sigma_r = 3 px: bias ≈ D (sigma_r/r)^2, std above Eq. 38."""
    mc = ep.monte_carlo_range_sigma(3.5e5, 3.0, n_trials=20_000, seed=4)
    r = float(ep.radius_px(3.5e5))
    assert mc.bias_km > 0.5 * 3.5e5 * (3.0 / r) ** 2
    assert mc.std_km > 1.01 * mc.linear_sigma_km


def test_paper_sigma_D_equals_sigma_r_needs_gaussian(rng):
    """Paper: r ~ N(r̄, sigma_r û), û uniform on the unit sphere, 'sigma_D = sigma_r'.  Not so."""
    s, n = 100.0, 200_000
    r_bar = np.array([0.0, 0.0, 3.0e5])
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    D_sphere = np.linalg.norm(r_bar + s * u, axis=1)
    assert abs(np.std(D_sphere) / ep.range_sigma_from_position_sigma(s, "sphere") - 1) < 0.01
    assert np.std(D_sphere) < 0.6 * s  # = s / sqrt(3), NOT s
    ball = u * rng.uniform(size=(n, 1)) ** (1 / 3)
    assert abs(np.std(np.linalg.norm(r_bar + s * ball, axis=1)) / ep.range_sigma_from_position_sigma(s, "ball") - 1) < 0.01
    D_gauss = np.linalg.norm(r_bar + s * rng.normal(size=(n, 3)), axis=1)
    assert abs(np.std(D_gauss) / ep.range_sigma_from_position_sigma(s, "gaussian") - 1) < 0.01


@pytest.mark.parametrize("theta_deg", [0.0, 8.0, 12.5])
def test_eq39_radial_and_tangential_against_monte_carlo(theta_deg):
    th = np.radians(theta_deg)
    s = 20e-6  # 4 arcsec attitude error
    d = ep.monte_carlo_center_attitude(th, s, n_trials=8000, seed=2)
    std = d.std(axis=0)
    assert abs(std[0] / ep.center_sigma_from_attitude(th, s) - 1) < 0.04  # Eq. 39, radial
    P = ep.center_covariance_from_attitude(th, s)
    assert abs(std[1] / np.sqrt(P[1, 1]) - 1) < 0.04  # tangential, f s / cos(theta)


def test_quaternion_sigma_is_half_the_angle_sigma(rng):
    """q = normalise(q̄ + [N(0, s_q) per vector axis, 0]) -> rotation-angle sigma 2 s_q (Eq. 39 slip)."""
    q0 = np.array([0.1, -0.3, 0.2, 0.927])
    C0 = quat_to_dcm(q0 / np.linalg.norm(q0))
    sq = 1e-5
    errs = []
    for _ in range(3000):
        # perturb by a small error quaternion  dq = [N(0, sq), 1] composed on the left
        dv = sq * rng.standard_normal(3)
        dq = np.r_[dv, 1.0] / np.linalg.norm(np.r_[dv, 1.0])
        dC = quat_to_dcm(dq)
        errs.append(attitude_error_vector(dC @ C0, C0))
    sd = np.std(np.asarray(errs), axis=0)
    np.testing.assert_allclose(sd, ep.angle_sigma_from_quaternion_sigma(sq), rtol=0.06)


def test_bad_input():
    with pytest.raises(GeometryError, match="range_km"):
        ep.range_sigma_from_radius_sigma(1000.0, 0.1)  # inside the Moon
    with pytest.raises(GeometryError, match="theta_rad"):
        ep.center_sigma_from_attitude(np.pi / 2, 1e-5)
    with pytest.raises(GeometryError, match="model"):
        ep.range_sigma_from_position_sigma(1.0, "cube")
    with pytest.raises(GeometryError, match="sigma_r_px"):
        ep.figure18_data(sigma_r_px=[-1.0])
