"""Quaternion <-> DCM conventions, validation, Davenport q-method and attitude from the body."""

import numpy as np
import pytest

from jaxlimb.errors import AttitudeError, GeometryError
from jaxlimb.geometry import attitude as att
from jaxlimb.geometry.camera import Camera


def _rand_q(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def test_convention_frame_rotation_about_z():
    """q = [0,0,sin(a/2),cos(a/2)] is the frame rotation by +a about z (passive): x_i -> (cos a, -sin a, 0)."""
    a = 0.3
    C = att.quat_to_dcm([0, 0, np.sin(a / 2), np.cos(a / 2)])
    np.testing.assert_allclose(C @ [1, 0, 0], [np.cos(a), -np.sin(a), 0], atol=1e-15)
    # scalar-first gives the same matrix
    np.testing.assert_allclose(att.quat_to_dcm([np.cos(a / 2), 0, 0, np.sin(a / 2)], order="wxyz"), C, atol=1e-15)
    # agrees with the rotation-vector form
    np.testing.assert_allclose(att.rotation_vector_to_dcm([0, 0, a]), C, atol=1e-15)


def test_roundtrip_and_orders(rng):
    for _ in range(200):
        q = _rand_q(rng)
        C = att.quat_to_dcm(q)
        att.validate_dcm(C, tol=1e-12)
        q2 = att.dcm_to_quat(C)
        assert q2[3] >= 0
        np.testing.assert_allclose(q2, q * np.sign(q[3]), atol=1e-12)
        qf = att.dcm_to_quat(C, order="wxyz")
        np.testing.assert_allclose(qf, [q2[3], *q2[:3]], atol=1e-15)
        np.testing.assert_allclose(att.quat_to_dcm(qf, order="wxyz"), C, atol=1e-12)
    # near-180-degree rotations take the other Shepperd branches
    for axis in np.eye(3):
        q = np.r_[axis * np.sin(3.1 / 2), np.cos(3.1 / 2)]
        np.testing.assert_allclose(att.dcm_to_quat(att.quat_to_dcm(q)), q, atol=1e-12)


def test_composition_order(rng):
    """A(q) composes like DCMs: the error vector of A(dphi) C vs C is dphi."""
    C = att.quat_to_dcm(_rand_q(rng))
    dphi = np.array([1e-3, -2e-3, 0.5e-3])
    np.testing.assert_allclose(att.attitude_error_vector(att.rotation_vector_to_dcm(dphi) @ C, C), dphi, atol=1e-12)


@pytest.mark.parametrize(
    "C, match",
    [
        (np.diag([1.0, 1.0, -1.0]), "det"),
        (np.diag([1.0, 1.0, 1.01]), "orthonormal"),
        (np.ones((3, 3)), "orthonormal"),
        (np.eye(2), "3x3"),
        (np.full((3, 3), np.nan), "finite"),
    ],
)
def test_invalid_dcm(C, match):
    with pytest.raises(AttitudeError, match=match):
        att.validate_dcm(C)
    with pytest.raises(AttitudeError):
        att.dcm_to_quat(C)


def test_invalid_quaternion():
    with pytest.raises(AttitudeError, match="unit norm"):
        att.quat_to_dcm([0, 0, 0, 2.0])
    with pytest.raises(AttitudeError, match="order"):
        att.quat_to_dcm([0, 0, 0, 1.0], order="sxyz")
    with pytest.raises(AttitudeError, match="shape"):
        att.quat_to_dcm([0, 0, 1.0])


def test_davenport_exact_and_degenerate(rng):
    C = att.quat_to_dcm(_rand_q(rng))
    r = rng.normal(size=(4, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    b = r @ C.T
    np.testing.assert_allclose(att.davenport_q_method(b, r, np.ones(4)), C, atol=1e-12)
    with pytest.raises(GeometryError, match="non-parallel"):
        att.davenport_q_method(np.stack([b[0], b[0]]), np.stack([r[0], r[0]]), np.ones(2))


def _scene(rng):
    C = att.quat_to_dcm(_rand_q(rng))
    r_obs = np.array([1.0e4, -2.0e4, 5.0e3])
    r_moon = np.array([-3.0e5, 2.0e5, 5.0e4])
    r_sun = np.array([1.2e8, 8.0e7, 3.0e7])
    return C, r_obs, r_moon, r_sun


def test_attitude_from_body_noise_free(rng):
    C, r_obs, r_moon, r_sun = _scene(rng)
    u_i = (r_moon - r_obs) / np.linalg.norm(r_moon - r_obs)
    b1 = C @ u_i
    b2 = C @ att.symmetry_axis_vectors(u_i, r_sun - r_moon)
    sol = att.attitude_from_body(b1, b2, r_moon, r_sun, r_obs, 1e-5, 1e-3)
    assert att.attitude_error_angle(sol.C_ci, C) < 1e-11
    np.testing.assert_allclose(sol.sigma_about_body_rad, 1e-3, rtol=1e-9)
    np.testing.assert_allclose(sol.sigma_cross_rad, 1e-5, rtol=1e-3)


def test_symmetry_axis_from_image_pixels(rng):
    """The image-measured axis (angle at the centre pixel) lifted to 3-D equals the true one."""
    cam = Camera(k1=-0.03)
    C, r_obs, r_moon, r_sun = _scene(rng)
    # point the camera so that the Moon is off-axis in the frame
    u_i = (r_moon - r_obs) / np.linalg.norm(r_moon - r_obs)
    tilt = att.rotation_vector_to_dcm([0.05, -0.08, 0.3])
    b1_cam = np.array([0.05, -0.08, 1.0])
    b1_cam /= np.linalg.norm(b1_cam)
    # build C so that C u_i = b1_cam (two-vector with an arbitrary roll)
    C = att.davenport_q_method(np.stack([b1_cam, tilt @ [1.0, 0, 0]]), np.stack([u_i, att.symmetry_axis_vectors(u_i, [0, 0, 1.0])]), [1e6, 1.0])
    b2_true = C @ att.symmetry_axis_vectors(u_i, r_sun - r_moon)
    rc = cam.project(C @ u_i)
    rc2 = cam.project(C @ u_i + 1e-7 * b2_true)
    ang = np.arctan2(rc2[0] - rc[0], rc2[1] - rc[1])
    b2 = att.symmetry_axis_camera(cam, rc, ang)
    np.testing.assert_allclose(b2, b2_true, atol=1e-6)


def test_attitude_from_body_monte_carlo():
    """Accuracy table: cross-axis ≈ sigma_center, about-body ≈ sigma_axis (weakly observable)."""
    rng = np.random.default_rng(3)
    C, r_obs, r_moon, r_sun = _scene(rng)
    s_c = 0.2 / 7272.7  # 0.2 px centre error on the default camera (rad)
    s_a = np.radians(0.5)  # 0.5 deg symmetry-axis error
    acc = att.attitude_from_body_accuracy(C, r_moon, r_sun, r_obs, s_c, s_a, n_trials=1500, seed=11)
    assert abs(acc.rms_about_body_arcsec / acc.predicted_about_body_arcsec - 1) < 0.08
    assert abs(acc.rms_cross_arcsec / acc.predicted_cross_arcsec - 1) < 0.08
    assert 2.7 < acc.mean_nees < 3.3
    # weak observability: the rotation about the body direction is ~ s_a / s_c ~ 300x worse
    assert acc.rms_about_body_arcsec > 100 * acc.rms_cross_arcsec


def test_full_phase_is_degenerate(rng):
    C, r_obs, r_moon, _ = _scene(rng)
    sun_behind_observer = r_moon + 1e8 * (r_obs - r_moon) / np.linalg.norm(r_obs - r_moon)
    u = C @ ((r_moon - r_obs) / np.linalg.norm(r_moon - r_obs))
    with pytest.raises(GeometryError, match="phase angle 0 or 180"):
        att.attitude_from_body(u, [1.0, 0, 0], r_moon, sun_behind_observer, r_obs, 1e-5, 1e-3)
    with pytest.raises(GeometryError, match="sigma_axis_rad"):
        att.attitude_from_body(u, [1.0, 0, 0], r_moon, r_moon + [1e8, 0, 0], r_obs, 1e-5, 0.0)
