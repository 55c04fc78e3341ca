"""Tests of the limb cone (Eq. 1-9 of Mortari et al. 2016), the image conic, gamma_off and the terminator."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial.transform import Rotation

from jaxlimb.errors import AttitudeError, GeometryError, LimbInputError
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.conic import conic_eval, conic_to_ellipse, ellipse_points, ellipse_to_conic
from jaxlimb.geometry.ellipsoid import (gamma_off, gamma_off_direction, gamma_off_signed, image_conic, limb_cone,
                                        limb_cone_matrix)
from jaxlimb.geometry.terminator import terminator_ellipse, terminator_image

EARTH = (6378.137, 6378.137, 6356.752)
MOON = 1737.4


def _ray_disc(radii, p, v):
    """Relative discriminant of the ray p + t v against x^T J x = 1 (0 = tangent)."""
    J = np.diag(np.asarray(radii, float) ** -2.0)
    a, b, c = v @ J @ v, v @ J @ p, p @ J @ p - 1.0
    return (b * b - a * c) / (b * b)


# ------------------------------------------------------------------------------ Eq. 2-6
radii_st = st.tuples(*[st.floats(0.05, 20.0)] * 3)
dir_st = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


@settings(max_examples=150, deadline=None)
@given(radii=radii_st, d=dir_st, k=st.floats(1.001, 1e4))
def test_limb_cone_sign_structure_and_determinant(radii, d, k):
    """Sec. III-A: one positive and two negative eigenvalues; det M = (1 - gamma)^2 det J (Eq. 6)."""
    r = np.asarray(radii)
    u = np.asarray(d) / np.linalg.norm(d)
    # place the observer outside: scale the direction to the surface, then by k > 1
    p = k * u / math.sqrt(np.sum((u / r) ** 2))
    M = limb_cone_matrix(r, p)
    gamma = float(np.sum((p / r) ** 2))
    assert gamma > 1
    detJ = float(np.prod(r**-2.0))
    assert np.linalg.det(M) == pytest.approx((1 - gamma) ** 2 * detJ, rel=1e-6)
    lam = np.linalg.eigvalsh(M)
    assert lam[0] < 0 and lam[1] < 0 and lam[2] > 0
    cone = limb_cone(r, p)
    assert cone.eigenvalues[0] < 0 and cone.eigenvalues[1] < 0 and cone.eigenvalues[2] > 0
    assert abs(cone.eigenvalues[0]) <= abs(cone.eigenvalues[1])
    assert 0 < cone.semi_axes[1] <= cone.semi_axes[0] < 1
    assert np.allclose(cone.C_ie.T @ cone.C_ie, np.eye(3), atol=1e-10)
    assert np.linalg.det(cone.C_ie) == pytest.approx(1.0)
    assert cone.axis @ (-p) > 0


def test_sphere_cone_is_circular_and_centered():
    p = np.array([3000.0, -40000.0, 12000.0])
    cone = limb_cone(MOON, p)
    D = np.linalg.norm(p)
    assert cone.semi_axes[0] == pytest.approx(MOON / D, rel=1e-12)
    assert cone.semi_axes[1] == pytest.approx(MOON / D, rel=1e-12)
    assert cone.rho == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(cone.axis, -p / D, atol=1e-12)
    assert cone.gamma_off == pytest.approx(0.0, abs=1e-9)
    assert np.allclose(gamma_off_direction(MOON, p), 0.0)


def test_cone_directions_are_tangent_and_axis_hits():
    R = Rotation.from_euler("xyz", [0.3, -0.7, 1.1]).as_matrix()
    radii = (60.0, 45.0, 40.0)
    p = R @ np.array([300.0, 20.0, 50.0])
    cone = limb_cone(radii, p)
    for v in cone.directions(np.linspace(0, 2 * np.pi, 37)):
        assert abs(_ray_disc(radii, p, v)) < 1e-10
    # slightly inside / outside the cone: hit / miss
    a_, b_ = cone.semi_axes
    w_in = np.array([0.99 * a_, 0.0, math.sqrt(1 - (0.99 * a_) ** 2)])
    w_out = np.array([1.01 * a_, 0.0, math.sqrt(1 - (1.01 * a_) ** 2)])
    assert _ray_disc(radii, p, cone.C_ie @ w_in) > 0
    assert _ray_disc(radii, p, cone.C_ie @ w_out) < 0
    assert _ray_disc(radii, p, cone.axis) > 0


def _meridian_tangent_slopes(Re, Rp, rho_p, z_p):
    """Sec. IV: slopes m_{1,2} of the two tangents from (rho_p, z_p) to the meridian ellipse."""
    s = math.sqrt(rho_p**2 * Rp**2 + z_p**2 * Re**2 - Re**2 * Rp**2)
    den = rho_p**2 - Re**2
    return (rho_p * z_p + s) / den, (rho_p * z_p - s) / den


@pytest.mark.parametrize("lat_deg", [0.0, 20.0, 45.0, 70.0, -35.0])
@pytest.mark.parametrize("dist", [42164.0, 384400.0, 12000.0])
def test_earth_minor_axis_and_gamma_off_vs_meridian_tangents(lat_deg, dist):
    """b' = sin(delta_theta/2) (Sec. IV) and gamma_off = angle between the tangents' bisector and -p."""
    Re, Rp = EARTH[0], EARTH[2]
    la = math.radians(lat_deg)
    rho_p, z_p = dist * math.cos(la), dist * math.sin(la)
    p = np.array([rho_p, 0.0, z_p])
    cone = limb_cone(EARTH, p)
    m1, m2 = _meridian_tangent_slopes(Re, Rp, rho_p, z_p)
    # tangent lines, oriented from the observer toward the body
    to_c = -np.array([rho_p, z_p])
    t1 = np.array([1.0, m1]) / math.hypot(1, m1)
    t2 = np.array([1.0, m2]) / math.hypot(1, m2)
    t1, t2 = t1 * np.sign(t1 @ to_c), t2 * np.sign(t2 @ to_c)
    dtheta = math.acos(float(t1 @ t2))
    assert cone.semi_axes[1] == pytest.approx(math.sin(dtheta / 2), rel=1e-9)
    bis = (t1 + t2) / np.linalg.norm(t1 + t2)
    to_center = -np.array([rho_p, z_p]) / dist
    g_ref = math.atan2(abs(bis[0] * to_center[1] - bis[1] * to_center[0]), float(bis @ to_center))
    assert cone.gamma_off == pytest.approx(g_ref, abs=1e-12)
    assert gamma_off(EARTH, p) == pytest.approx(g_ref, abs=1e-12)
    assert np.sign(gamma_off_signed(EARTH, p)) == np.sign(lat_deg) or lat_deg == 0
    if lat_deg != 0:
        # the axis turns toward the equator: toward -pole for a northern observer
        assert np.sign(gamma_off_direction(EARTH, p)[2]) == -np.sign(lat_deg)
    assert cone.rho < 1


def test_gamma_off_earth_geo_magnitude():
    """Fig. 3 of Mortari et al. 2016: gamma_off is some arcseconds at GEO, 0 at the equator and the pole."""
    la = math.radians(45.0)
    g = gamma_off(EARTH, 42164.0 * np.array([math.cos(la), 0, math.sin(la)]))
    assert 1.0 < math.degrees(g) * 3600 < 60.0
    assert gamma_off(EARTH, [42164.0, 0, 0]) == pytest.approx(0.0, abs=1e-12)
    assert gamma_off(EARTH, [0, 0, 42164.0]) == pytest.approx(0.0, abs=1e-12)


# ------------------------------------------------------------------------------ errors
@pytest.mark.parametrize(
    "radii, p",
    [
        ((1.0, 1.0, 1.0), (0.5, 0.0, 0.0)),  # inside
        ((1.0, 2.0, 3.0), (1.0, 0.0, 0.0)),  # on the surface
        ((1.0, 0.0, 1.0), (5.0, 0.0, 0.0)),  # degenerate
        ((1.0, -1.0, 1.0), (5.0, 0.0, 0.0)),
        ((1.0, np.nan, 1.0), (5.0, 0.0, 0.0)),
        ((1.0, np.inf, 1.0), (5.0, 0.0, 0.0)),
        ((1.0, 1.0), (5.0, 0.0, 0.0)),
    ],
)
def test_bad_geometry_raises(radii, p):
    with pytest.raises(GeometryError):
        limb_cone_matrix(radii, p)
    with pytest.raises(GeometryError):
        limb_cone(radii, p)


def test_bad_vectors_and_rotations():
    with pytest.raises(LimbInputError):
        limb_cone(1.0, [np.nan, 0, 5])
    with pytest.raises(LimbInputError):
        limb_cone(1.0, [5.0, 0.0])
    cam = Camera()
    with pytest.raises(AttitudeError):
        image_conic(cam, MOON, [0, 0, 1e5], np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(AttitudeError):
        image_conic(cam, MOON, [0, 0, 1e5], 1.01 * np.eye(3))
    with pytest.raises(GeometryError):
        image_conic(cam, MOON, [0, 0, -1e5])  # behind the camera
    with pytest.raises(GeometryError):
        image_conic(cam, MOON, [0, 0, 1000.0])  # inside
    with pytest.raises(GeometryError):
        image_conic(cam, MOON, [1e5, 0, 10.0])  # limb cone crosses the image plane: not an ellipse


# ------------------------------------------------------------------------------ image conic
def test_image_conic_sphere_on_axis_is_the_circle():
    cam = Camera()
    ic = image_conic(cam, MOON, [0.0, 0.0, 384400.0])
    r = cam.radius_px(MOON, 384400.0)
    assert ic.semi_axes_px == pytest.approx((r, r), rel=1e-10)
    assert ic.center_rc == pytest.approx(cam.principal_point_rc, abs=1e-9)
    assert ic.body_center_rc == pytest.approx(cam.principal_point_rc, abs=1e-9)
    pts = ic.points(50)
    assert np.allclose(np.hypot(pts[:, 0] - 971.5, pts[:, 1] - 1295.5), r, rtol=1e-10)


def test_image_conic_sphere_off_axis_exact():
    """Sphere of angular radius a seen at off-axis angle t: the radial extremes are f tan(t -+ a)."""
    cam = Camera()
    u = cam.los(np.array([40.0, 60.0]))  # near the top-left corner
    D = 70000.0  # radius ~180 px
    ic = image_conic(cam, MOON, D * u)
    t = math.acos(u[2])
    a = math.asin(MOON / D)
    f = cam.focal_px
    r_in, r_out = f * math.tan(t - a), f * math.tan(t + a)
    pp = np.array(cam.principal_point_rc)
    radial = (np.array(ic.body_center_rc) - pp) / np.linalg.norm(np.array(ic.body_center_rc) - pp)
    center_dist = float((np.array(ic.center_rc) - pp) @ radial)
    assert center_dist == pytest.approx(0.5 * (r_in + r_out), abs=1e-6)
    assert ic.semi_axes_px[0] == pytest.approx(0.5 * (r_out - r_in), abs=1e-6)
    # the ellipse centre is displaced outward from the projected centre (perspective), ~1 px here
    off = np.array(ic.center_rc) - np.array(ic.body_center_rc)
    assert off @ radial > 0
    assert ic.center_offset_px == pytest.approx(0.5 * (r_in + r_out) - f * math.tan(t), abs=1e-6)
    assert 0.7 < ic.center_offset_px < 1.5
    # major axis is radial: angle convention (d_row, d_col) = (-sin, cos)
    th = ic.angle_rad
    major = np.array([-math.sin(th), math.cos(th)])
    assert abs(abs(major @ radial) - 1) < 1e-9


def test_image_conic_points_are_tangent_rays():
    cam = Camera()
    R = Rotation.from_euler("zyx", [0.4, -0.3, 0.9]).as_matrix()
    radii = (60.0, 45.0, 40.0)
    q = cam.los(np.array([300.0, 2000.0])) * 2500.0
    ic = image_conic(cam, radii, q, R)
    p_body = -R.T @ q
    for rc in ic.points(40):
        d = R.T @ cam.los(rc)
        assert abs(_ray_disc(radii, p_body, d)) < 1e-9
    assert ic.evaluate(np.array(ic.body_center_rc)) < 0
    assert ic.evaluate(np.array([0.0, 0.0])) > 0


def test_image_ellipse_ratio_matches_eq9_when_axis_on_boresight():
    """With the cone axis along +z the image plane cuts the cone orthogonally: semi-axes f tan(asin a'), f tan(asin b')."""
    la = math.radians(40.0)
    p = 30000.0 * np.array([math.cos(la), 0.0, math.sin(la)])
    cone = limb_cone(EARTH, p)
    R = cone.C_ie.T  # body -> cone frame; the axis goes to +z
    q = -R @ p
    cam = Camera()
    ic = image_conic(cam, EARTH, q, R)
    f = cam.focal_px
    assert ic.semi_axes_px[0] == pytest.approx(f * math.tan(math.asin(cone.semi_axes[0])), rel=1e-9)
    assert ic.semi_axes_px[1] == pytest.approx(f * math.tan(math.asin(cone.semi_axes[1])), rel=1e-9)
    assert ic.center_rc == pytest.approx(cam.principal_point_rc, abs=1e-7)
    # ... and the projected body centre is off by gamma_off
    d = math.hypot(ic.body_center_rc[0] - 971.5, ic.body_center_rc[1] - 1295.5)
    assert d == pytest.approx(f * math.tan(cone.gamma_off), rel=1e-6)
    # w1 (major) maps to camera +x -> angle 0 (or pi)
    assert min(ic.angle_rad, math.pi - ic.angle_rad) < 1e-6


@settings(max_examples=60, deadline=None)
@given(
    r0=st.floats(-500, 500),
    c0=st.floats(-500, 500),
    a=st.floats(1.0, 400.0),
    ratio=st.floats(0.05, 0.98),
    th=st.floats(0.0, math.pi - 1e-9),
)
def test_conic_ellipse_round_trip(r0, c0, a, ratio, th):
    b = a * ratio
    C = ellipse_to_conic((r0, c0), (a, b), th)
    pts = ellipse_points((r0, c0), (a, b), th, np.linspace(0, 6, 13))
    assert np.allclose(conic_eval(C, pts), 0.0, atol=1e-9 * np.abs(C).max() * (1 + a * a))
    (rr, cc), (aa, bb), tt = conic_to_ellipse(C)
    assert (rr, cc) == pytest.approx((r0, c0), abs=1e-6 * (1 + a))
    assert (aa, bb) == pytest.approx((a, b), rel=1e-7)
    dth = (tt - th + math.pi / 2) % math.pi - math.pi / 2
    assert abs(dth) < 1e-6


def test_conic_to_ellipse_rejects_non_ellipses():
    with pytest.raises(GeometryError):
        conic_to_ellipse(np.diag([1.0, -1.0, -1.0]))  # hyperbola
    with pytest.raises(GeometryError):
        conic_to_ellipse(np.diag([1.0, 1.0, 1.0]))  # imaginary
    with pytest.raises(GeometryError):
        conic_to_ellipse(np.zeros((2, 2)))


def test_angle_convention_matches_sigmoid_model():
    """Our angle_rad equals EllipseParams.theta: the model's ellipse coincides with ours."""
    from jaxlimb.models.sigmoid import EllipseParams, ellipse_points as model_points

    th = 0.6
    C = ellipse_to_conic((100.0, 200.0), (50.0, 30.0), th)
    p = EllipseParams(r0=100.0, c0=200.0, a=50.0, theta=th, rho=0.6, k=1.0, ymax=1.0, ymin=0.0)
    pts = np.asarray(model_points(p, np.linspace(0, 6, 9)))
    assert np.allclose(conic_eval(C, pts), 0.0, atol=1e-12)
    # the major axis is counter-clockwise from +col as displayed: positive theta moves it up (-row)
    top = ellipse_points((100.0, 200.0), (50.0, 30.0), th, np.array([0.0]))[0]
    assert top[0] < 100.0 and top[1] > 200.0


# ------------------------------------------------------------------------------ terminator
@pytest.mark.parametrize("radii", [(MOON,) * 3, EARTH, (60.0, 45.0, 40.0)])
def test_terminator_ellipse_properties(radii, rng):
    for _ in range(5):
        s = rng.normal(size=3)
        s /= np.linalg.norm(s)
        term = terminator_ellipse(radii, s)
        x = term.points(np.linspace(0, 2 * np.pi, 25))
        J = np.asarray(radii) ** -2.0
        assert np.allclose(np.sum(x * x * J, axis=1), 1.0, atol=1e-12)
        assert np.allclose((x * J) @ s, 0.0, atol=1e-12)
        assert abs(term.axes[0] @ term.axes[1]) < 1e-9 * term.semi_axes[0] ** 2
        assert term.semi_axes[0] >= term.semi_axes[1]
        assert np.allclose(term.center, 0.0)
    # sphere: the great circle perpendicular to the Sun
    term = terminator_ellipse(MOON, [0.0, 0.6, 0.8])
    assert term.semi_axes == pytest.approx((MOON, MOON))
    assert np.allclose(term.normal, [0.0, 0.6, 0.8])


def test_terminator_image_conic_contains_visible_points():
    cam = Camera()
    R = Rotation.from_euler("zyx", [0.2, 0.1, -0.4]).as_matrix()
    q = cam.los(np.array([800.0, 1500.0])) * 30000.0
    s = np.array([0.8, -0.3, -0.5])
    ti = terminator_image(cam, EARTH, q, R, s)
    assert ti.conic is not None
    pts = ti.visible_points_rc(720)
    assert len(pts) > 100
    val = conic_eval(ti.conic, pts)
    g = np.abs(conic_eval(ti.conic, pts + [0.5, 0.0]) - val) * 2
    assert np.max(np.abs(val) / g) < 1e-6  # well below a pixel (first-order distance)
    # visible points lie on the disk (inside the limb)
    assert np.all(image_conic(cam, EARTH, q, R).evaluate(pts) < 0)


def test_terminator_edge_on_has_no_conic():
    cam = Camera()
    q = np.array([0.0, 0.0, 100000.0])
    ti = terminator_image(cam, MOON, q, np.eye(3), [1.0, 0.0, 0.0])  # half Moon: plane contains the camera
    assert ti.conic is None
    pts = ti.visible_points_rc(400)
    assert np.allclose(pts[:, 1], 971.5 * 0 + 1295.5, atol=1e-6)  # the terminator is the central column
    with pytest.raises(LimbInputError):
        terminator_image(cam, MOON, q, np.eye(3), [0.0, 0.0, 0.0])
