"""Earth centre offset (gamma_off), meridian tangent slopes and the range iteration (§IV)."""

import math

import numpy as np
import pytest

from jaxlimb.errors import GeometryError
from jaxlimb.geometry import earth as E
from jaxlimb.geometry.ellipsoid import limb_cone

RE, RP = E.EARTH_EQUATORIAL_KM, E.EARTH_POLAR_KM


def _pos(D, lat_deg, lon=0.7):
    la = math.radians(lat_deg)
    return D * np.array([math.cos(la) * math.cos(lon), math.cos(la) * math.sin(lon), math.sin(la)])


@pytest.mark.parametrize("rho_p, z_p", [(4.0e4, 1.2e4), (1.0e5, -3.0e4), (2.0e3, 4.0e4), (3.0e5, 0.0)])
def test_paper_slopes_match_tangent_points(rho_p, z_p):
    m1, m2 = E.tangent_slopes(rho_p, z_p, RE, RP)
    d1, d2 = E.meridian_tangent_directions(rho_p, z_p, RE, RP)
    assert sorted([m1, m2]) == pytest.approx(sorted([d1[1] / d1[0], d2[1] / d2[0]]), rel=1e-10)
    assert E.limb_angle_from_slopes(m1, m2) == pytest.approx(E.meridian_limb_angle(rho_p, z_p, RE, RP), rel=1e-10)
    # both tangent lines really touch the ellipse: k^2 = Re^2 m^2 + Rp^2
    for m in (m1, m2):
        k = z_p - m * rho_p
        assert k * k == pytest.approx(RE**2 * m * m + RP**2, rel=1e-10)


def test_slope_angle_ambiguity_near_the_pole():
    """Above the pole the two tangent lines straddle the vertical: atan2(|dm|, 1 + m1 m2) gives
    pi - dtheta; the acute-angle form is right (observer beyond sqrt(2) Re)."""
    m1, m2 = E.tangent_slopes(2.0e3, 4.0e4, RE, RP)
    true = E.meridian_limb_angle(2.0e3, 4.0e4, RE, RP)
    assert 1 + m1 * m2 < 0
    assert math.atan2(abs(m1 - m2), 1 + m1 * m2) == pytest.approx(math.pi - true, rel=1e-10)
    assert E.limb_angle_from_slopes(m1, m2) == pytest.approx(true, rel=1e-10)


def test_paper_slope_singular_at_rho_equal_Re():
    with pytest.raises(GeometryError, match="infinite"):
        E.tangent_slopes(RE, 3.0e4, RE, RP)
    assert 0 < E.meridian_limb_angle(RE, 3.0e4, RE, RP) < math.pi  # robust form works


@pytest.mark.parametrize("D", [E.GEO_RADIUS_KM, 1.0e5, E.MOON_DISTANCE_KM])
@pytest.mark.parametrize("lat", [0.0, 20.0, 55.0, -40.0, 89.0])
@pytest.mark.parametrize("h", [0.0, 60.0])
def test_meridian_angle_equals_minor_axis_angle_at_truth(D, lat, h):
    """sin(dtheta_tilde/2) = b' (Eq. 8) equals the meridian tangent angle exactly at the true p."""
    p = _pos(D, lat)
    cone = limb_cone(E.earth_radii(h), p)
    rho, z = E.meridian_coordinates(p)
    Re, Rp = RE + h, RP + h
    assert E.meridian_limb_angle(rho, z, Re, Rp) == pytest.approx(E.limb_angle_from_b_prime(cone.semi_axes[1]), rel=1e-12, abs=1e-15)


def test_sphere_derivative_and_paper_factor():
    """d(dtheta)/dp = -2R/(p^2 sqrt(1-R^2/p^2)) = -2 sin^2(dtheta/2)/(R cos(dtheta/2)):
    the paper's factor R cos/(2 sin^2) is exactly 1/|d dtheta/dp|, but its sign is wrong."""
    R, p, h = 6371.0, 8.0e4, 1e-3
    dth = lambda q: 2 * math.asin(R / q)  # noqa: E731
    num = (dth(p + h) - dth(p - h)) / (2 * h)
    ana = -2 * R / (p * p * math.sqrt(1 - R * R / (p * p)))
    assert num == pytest.approx(ana, rel=1e-8)
    t = dth(p)
    assert ana == pytest.approx(-2 * math.sin(t / 2) ** 2 / (R * math.cos(t / 2)), rel=1e-12)
    # prior too short (p0 < p): predicted angle larger than measured -> must move OUT
    p0 = 0.95 * p
    hat, tilde = dth(p0), dth(p)
    assert hat > tilde
    dp_paper = E.delta_p(hat, tilde, R, hat, sign="paper")
    dp_fixed = E.delta_p(hat, tilde, R, hat, sign="corrected")
    assert dp_paper < 0 < dp_fixed  # the printed sign moves the wrong way
    assert abs(p0 + dp_fixed - p) < 0.1 * abs(p0 - p)  # Newton: 5 % error -> 0.25 %
    assert abs(p0 + dp_paper - p) > abs(p0 - p)


def test_gamma_off_sign_and_correction():
    for lat in (35.0, -35.0):
        p = _pos(8.0e4, lat)
        cone = limb_cone(E.earth_radii(), p)
        g = E.gamma_off(p)
        assert math.copysign(1, g) == math.copysign(1, lat)
        assert abs(g) == pytest.approx(cone.gamma_off, rel=1e-12)
        u = E.center_direction(cone.axis, g)
        np.testing.assert_allclose(u, -p / np.linalg.norm(p), atol=1e-15)
    assert E.gamma_off(_pos(8.0e4, 0.0)) == 0.0


def test_gamma_off_independent_bisector_check():
    """The cone axis is the bisector of the two meridian tangent rays (symmetry plane)."""
    p = _pos(6.0e4, 40.0, lon=0.0)  # meridian plane = x-z plane
    rho, z = E.meridian_coordinates(p)
    d1, d2 = E.meridian_tangent_directions(rho, z, RE, RP)
    b = (d1 + d2) / np.linalg.norm(d1 + d2)
    bis = np.array([b[0], 0.0, b[1]])
    axis = limb_cone(E.earth_radii(), p).axis
    np.testing.assert_allclose(axis, bis, atol=1e-13)
    ang = math.acos(np.clip(bis @ (-p / np.linalg.norm(p)), -1, 1))
    assert ang == pytest.approx(abs(E.gamma_off(p)), rel=1e-6)


def test_gamma_off_surface_fig3():
    s = E.gamma_off_surface(latitudes_deg=np.linspace(0, 90, 19), distances_km=np.linspace(E.GEO_RADIUS_KM, E.MOON_DISTANCE_KM, 8))
    g = s.gamma_off_arcsec
    assert g.shape == (19, 8)
    np.testing.assert_allclose(g[0], 0.0, atol=1e-9)  # equator
    np.testing.assert_allclose(g[-1], 0.0, atol=1e-6)  # pole
    assert np.all(g[1:-1] > 0)
    assert np.all(np.diff(g[1:-1], axis=1) < 0)  # decreasing with distance
    i = int(np.argmax(g[:, 0]))
    assert 40 <= s.latitudes_deg[i] <= 50  # maximum near 45 deg
    assert 10 < g[i, 0] < 25  # ~16 arcsec at GEO
    assert g[i, -1] < 0.3  # ~0.19 arcsec at the Moon's distance
    assert np.all(s.rho <= 1.0) and np.all(s.rho > 0.99)
    # atmosphere (both radii + h): the larger apparent size outweighs the smaller flattening
    # ratio: +60 km -> +0.9 % at GEO, 45 deg (15.80" -> 15.95")
    s60 = E.gamma_off_surface(latitudes_deg=[45.0], distances_km=[E.GEO_RADIUS_KM], atmosphere_km=60.0)
    assert g[9, 0] < s60.gamma_off_arcsec[0, 0] < 1.02 * g[9, 0]


def _measure(p, h=0.0):
    cone = limb_cone(E.earth_radii(h), p)
    return cone.axis, cone.semi_axes[1]


@pytest.mark.parametrize("update", ["newton", "ratio"])
def test_range_iteration_converges(update):
    """Tolerance = 1 m of range; prior error 10 km (Orion 3-sigma) and 1000 km."""
    rng = np.random.default_rng(8)
    for D in (E.GEO_RADIUS_KM, 1.5e5, E.MOON_DISTANCE_KM):
        eps = 2 * RE / D**2 * 1e-3
        for lat in (5.0, 45.0, -70.0):
            p = _pos(D, lat)
            v, b = _measure(p, 30.0)
            for err, max_it in ((10.0, 2), (1000.0, 3 if update == "newton" else 2)):
                e = rng.normal(size=3)
                fix = E.earth_range_iteration(v, b, p + err * e / np.linalg.norm(e), atmosphere_km=30.0, eps=eps, update=update)
                assert fix.converged
                assert fix.iterations <= max_it, (D, lat, err, fix.iterations)
                assert np.linalg.norm(fix.position_km - p) < 2e-3  # km
                assert len(fix.history) == fix.iterations + 1


def test_range_iteration_paper_sign_diverges():
    p = _pos(1.0e5, 30.0)
    v, b = _measure(p)
    fix = E.earth_range_iteration(v, b, p * 1.01, eps=1e-10, sign="paper", max_iter=8)
    assert not fix.converged
    assert abs(fix.range_km - 1.0e5) > 1.0e5 * 0.01  # further away than the prior


def test_bad_inputs():
    with pytest.raises(GeometryError, match="outside"):
        E.gamma_off([1000.0, 0.0, 2000.0])
    with pytest.raises(GeometryError, match="outside"):
        E.meridian_limb_angle(6000.0, 0.0, RE, RP)
    with pytest.raises(GeometryError, match="radii"):
        limb_cone((RE, 0.0, RP), [4e4, 0, 0])
    with pytest.raises(GeometryError, match="polar_km"):
        E.earth_radii(0.0, RE, -1.0)
    with pytest.raises(GeometryError, match="b_prime"):
        E.limb_angle_from_b_prime(1.2)
    v, b = _measure(_pos(5e4, 10.0))
    with pytest.raises(GeometryError, match="outside"):
        E.earth_range_iteration(v, b, [100.0, 0.0, 0.0])
    with pytest.raises(GeometryError, match="bad option"):
        E.earth_range_iteration(v, b, _pos(5e4, 10.0), R="mean")
