"""Brown-Conrady distortion, pixel <-> LOS through it, range from apparent size (sphere, off-axis)."""

import json
import math

import numpy as np
import pytest

from jaxlimb.errors import ConfigError
from jaxlimb.geometry.camera import Camera, sphere_image_ellipse

LENS = dict(k1=-0.12, k2=0.03, k3=-0.004, p1=3e-4, p2=-2e-4)


def _grid(cam, n=15):
    r = np.linspace(0, cam.rows - 1, n)
    c = np.linspace(0, cam.cols - 1, n)
    return np.stack(np.meshgrid(r, c, indexing="ij"), axis=-1).reshape(-1, 2)


def test_default_is_pinhole_and_json_keys_unchanged(tmp_path):
    cam = Camera()
    assert not cam.has_distortion
    assert set(cam.to_dict()) == {"focal_length_mm", "pixel_pitch_mm", "rows", "cols", "principal_point_rc"}
    xyz = np.array([[0.1, -0.2, 1.0], [3.0, 4.0, 50.0]])
    f = cam.focal_px
    np.testing.assert_array_equal(cam.project(xyz)[:, 1], cam.principal_point_rc[1] + f * xyz[:, 0] / xyz[:, 2])
    rc = _grid(cam, 4)
    np.testing.assert_array_equal(cam.undistort(rc), rc)
    # distortion keys are optional in the camera file, and round-trip
    d = cam.to_dict() | {"k1": -0.1, "p2": 1e-4}
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(d))
    cam2 = Camera.from_json(path)
    assert cam2.k1 == -0.1 and cam2.p2 == 1e-4 and cam2.k2 == 0.0
    assert Camera.from_dict(cam2.to_dict()) == cam2


def test_roundtrip_1e9_px():
    cam = Camera(**LENS)
    rc = _grid(cam)
    back = cam.undistort(cam.distort(rc))
    assert np.max(np.abs(back - rc)) < 1e-9
    back2 = cam.distort(cam.undistort(rc))
    assert np.max(np.abs(back2 - rc)) < 1e-9
    # the distortion is not negligible (several px at the corner)
    assert np.max(np.abs(cam.distort(rc) - rc)) > 5.0


def test_jacobian_matches_finite_differences():
    cam = Camera(**LENS)
    xy = np.array([[0.1, -0.15], [-0.17, 0.12], [0.0, 0.0]])
    J = cam.distort_jacobian_normalized(xy)
    h = 1e-7
    for i in range(2):
        d = np.zeros(2)
        d[i] = h
        num = (cam.distort_normalized(xy + d) - cam.distort_normalized(xy - d)) / (2 * h)
        np.testing.assert_allclose(J[:, :, i], num, atol=1e-8)
    rc = np.array([[100.0, 2400.0], [971.5, 1295.5]])
    G = cam.los_jacobian(rc)
    for i in range(2):
        d = np.zeros(2)
        d[i] = 1e-4
        num = (cam.los(rc + d) - cam.los(rc - d)) / 2e-4
        np.testing.assert_allclose(G[:, :, i], num, atol=1e-11)


def test_los_project_roundtrip_through_distortion(rng):
    cam = Camera(**LENS)
    rc = _grid(cam, 9)
    u = cam.los(rc)
    np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0, atol=1e-15)
    assert np.max(np.abs(cam.los_to_pixel(u) - rc)) < 1e-9
    # the ideal-pinhole LOS of the *undistorted* pixel is the same ray
    pin = Camera()
    np.testing.assert_allclose(pin.los(cam.undistort(rc)), u, atol=1e-14)


def test_bad_distortion():
    with pytest.raises(ConfigError, match="folds over"):
        Camera(k1=-6.0)
    with pytest.raises(ConfigError, match="k2"):
        Camera(k2=float("nan"))
    with pytest.raises(ConfigError, match="unknown keys"):
        Camera.from_dict({"focal_length_mm": 16, "pixel_pitch_mm": 0.0022, "rows": 10, "cols": 10, "k4": 0.1})


def test_range_from_radius_on_axis():
    cam = Camera()
    for D in (5e4, 1.5e5, 3.844e5):
        r = cam.radius_px(1737.4, D)
        # Eq. 36 of the 2015 paper: r = (f/d) R / sqrt(D^2 - R^2)
        assert math.isclose(r, cam.focal_px * 1737.4 / math.sqrt(D * D - 1737.4**2), rel_tol=1e-13)
        assert math.isclose(cam.range_from_radius(r, 1737.4), D, rel_tol=1e-12)
    with pytest.raises(ConfigError, match="radius_px"):
        cam.range_from_radius(-1.0, 1737.4)


def _limb_pixels(cam, center_cam, R, n=720):
    D = np.linalg.norm(center_cam)
    u = center_cam / D
    a = math.asin(R / D)
    e1 = np.cross(u, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    v = math.cos(a) * u + math.sin(a) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    return cam.project(v)


@pytest.mark.parametrize("D", [5.0e4, 3.844e5])
def test_off_axis_sphere_ellipse_and_exact_range(D):
    """Off-axis: the projected limb is the ellipse of sphere_image_ellipse and b^2/(a f) = tan(alpha)."""
    cam = Camera()
    corner = cam.los(np.array([150.0, 2450.0]))
    c = D * corner
    el = sphere_image_ellipse(cam, c, 1737.4)
    pts = _limb_pixels(cam, c, 1737.4)
    # every limb pixel satisfies the ellipse equation
    r0, c0 = el["center_rc"]
    a, b = el["semi_axes_px"]
    ph = el["angle_rad"]
    dr, dc = pts[:, 0] - r0, pts[:, 1] - c0
    # ellipsoid.py convention: semi-major axis along (d_row, d_col) = (-sin ph, cos ph)
    x = dc * math.cos(ph) - dr * math.sin(ph)
    y = dc * math.sin(ph) + dr * math.cos(ph)
    np.testing.assert_allclose((x / a) ** 2 + (y / b) ** 2, 1.0, atol=1e-9)
    assert math.isclose(cam.range_from_ellipse(a, b, 1737.4), D, rel_tol=1e-11)
    # the on-axis formula applied to the tangential semi-axis is short by exactly cos(theta)
    th = el["theta_rad"]
    D_naive = cam.range_from_radius(b, 1737.4)
    assert math.isclose(D_naive / D, math.cos(th), rel_tol=1e-10)
    assert 1 - D_naive / D > 0.015  # 1.8 % at this off-axis position (11 deg)
    # cross-check with the other engineer's general conic code when present
    ell = pytest.importorskip("jaxlimb.geometry.ellipsoid")
    if hasattr(ell, "image_conic"):
        ic = ell.image_conic(cam, (1737.4, 1737.4, 1737.4), c, np.eye(3))
        np.testing.assert_allclose(sorted(ic.semi_axes_px), sorted(el["semi_axes_px"]), rtol=1e-8)
        np.testing.assert_allclose(ic.center_rc, el["center_rc"], atol=1e-6)
        assert abs(math.sin(ic.angle_rad - el["angle_rad"])) < 1e-6
