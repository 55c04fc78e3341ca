"""The measurement model against the numpy sphere geometry: what ``locate`` reports with the camera it was given."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb.geometry.camera import Camera, sphere_image_ellipse
from jaxlimb.geometry.sphere_image import sphere_from_ellipse_center
from jaxlimb.track.measurement import MOON_RADIUS_KM, predict

jax.config.update("jax_enable_x64", True)

THETA = np.array([1000.0, 127.5, 127.5, 0.0])
NOMINAL = THETA * np.array([1.01, 1.0, 1.0, 1.0]) + np.array([0.0, 2.0, -1.5, 0.0])


def _camera(theta: np.ndarray) -> Camera:
    return Camera(focal_length_mm=theta[0] * 0.0022, pixel_pitch_mm=0.0022, rows=256, cols=256,
                  principal_point_rc=(float(theta[1]), float(theta[2])))


def _case(offset_rad: tuple[float, float], range_km: float) -> np.ndarray:
    """A camera-frame body centre ``offset_rad`` (x, y) off the boresight at ``range_km``."""
    v = np.array([np.tan(offset_rad[0]), np.tan(offset_rad[1]), 1.0])
    return range_km * v / np.linalg.norm(v)


def _predict(q: np.ndarray, theta: np.ndarray, theta_locate: np.ndarray, is_range: float) -> np.ndarray:
    return np.asarray(predict(jnp.zeros(3), jnp.asarray(theta), jnp.eye(3), jnp.asarray(q), MOON_RADIUS_KM,
                              is_range, jnp.asarray(theta_locate)))


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.12, -0.05), (-0.09, 0.11)])
@pytest.mark.parametrize("range_km", [40_000.0, 400_000.0])
def test_with_locates_own_camera_the_model_is_the_pinhole_image(offset, range_km):
    q = _case(offset, range_km)
    z = _predict(q, THETA, THETA, 0.0)
    pin = _camera(THETA).project(q / np.linalg.norm(q))
    alpha = np.arcsin(MOON_RADIUS_KM / range_km)
    np.testing.assert_allclose(z[:2], pin, atol=1e-9)
    np.testing.assert_allclose(z[2], THETA[0] * np.tan(alpha), rtol=1e-12)
    np.testing.assert_allclose(_predict(q, THETA, THETA, 1.0)[2], range_km, rtol=1e-12)


@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.12, -0.05), (-0.09, 0.11)])
@pytest.mark.parametrize("range_km", [40_000.0, 120_000.0])
def test_with_a_wrong_camera_the_model_is_what_locates_map_reports(offset, range_km):
    """The true camera's limb ellipse (``sphere_image_ellipse``) read back through ``locate``'s body-centre map
    with the nominal camera (``sphere_from_ellipse_center``): centre to 1e-8 px, radius and range to 1e-10."""
    q = _case(offset, range_km)
    ell = sphere_image_ellipse(_camera(THETA), q, MOON_RADIUS_KM)
    sph = sphere_from_ellipse_center(NOMINAL[0], NOMINAL[1:3], ell["center_rc"], ell["semi_axes_px"][0])
    z = _predict(q, THETA, NOMINAL, 0.0)
    np.testing.assert_allclose(z[:2], sph.body_center_rc, atol=1e-8)
    np.testing.assert_allclose(z[2], sph.radius_equivalent_px, rtol=1e-10)
    np.testing.assert_allclose(_predict(q, THETA, NOMINAL, 1.0)[2], MOON_RADIUS_KM / np.sin(sph.alpha_rad), rtol=1e-10)


def test_a_principal_point_error_leaks_sin2_alpha_into_the_centre():
    """The off-axis correction made with a shifted principal point moves the reported centre by about
    ``sin^2(alpha)`` of the shift, beyond the shift itself: the term the model must carry for the principal point
    to be estimated without bias."""
    q = _case((0.1, 0.05), 40_000.0)
    shifted = THETA + np.array([0.0, 2.0, -1.5, 0.0])
    z_true, z_shift = _predict(q, THETA, THETA, 0.0), _predict(q, THETA, shifted, 0.0)
    s2 = (MOON_RADIUS_KM / 40_000.0) ** 2
    leak = z_shift[:2] - z_true[:2]
    np.testing.assert_allclose(leak, s2 * np.array([2.0, -1.5]), rtol=0.1)
    assert np.all(np.abs(leak) > 1e-3)


def _record(cov_names: tuple[str, ...]) -> dict:
    full = {"center_r": {"center_r": 4e-4, "center_c": 1e-4, "radius": 2e-5},
            "center_c": {"center_r": 1e-4, "center_c": 9e-4, "radius": -3e-5},
            "radius": {"center_r": 2e-5, "center_c": -3e-5, "radius": 1e-3}}
    cov = {a: {b: full[a][b] for b in cov_names} for a in cov_names}
    return {"covariance": cov, "covariance_noise": cov, "center_rc": [10.0, 20.0], "radius_px": 6.0}


def test_a_frame_with_the_centres_covariance_alone_keeps_its_centre():
    from jaxlimb.errors import ConfigError
    from jaxlimb.track.measurement import frame_covariances

    names = ("center_r", "center_c", "radius")
    cov, noise = frame_covariances(_record(names), names, 6.0, "f")
    assert cov.shape == (3, 3) and cov[2, 2] == 1e-3
    cov, noise = frame_covariances(_record(names[:2]), names, 6.0, "f")
    np.testing.assert_allclose(cov[:2, :2], [[4e-4, 1e-4], [1e-4, 9e-4]])
    assert cov[2, 2] == noise[2, 2] == 60.0**2 and not cov[:2, 2].any()
    with pytest.raises(ConfigError, match="no covariance"):
        frame_covariances({"covariance": {}}, names, 6.0, "f")
    with pytest.raises(ConfigError, match="no covariance"):
        frame_covariances(_record(names[:2]), names, None, "f")
