"""Earth pipeline with a lens-distorted camera: measured in the resampled ideal image, mapped back."""

from __future__ import annotations

import cv2
import numpy as np

from jaxlimb.geometry.camera import Camera
from jaxlimb.imaging.undistort import pinhole_of, undistort_image
from jaxlimb.pipeline import locate
from jaxlimb.render import RenderOptions, earth_scene, render_body


def _distorted_frame(img: np.ndarray, cam: Camera) -> np.ndarray:
    """The frame a distorted ``cam`` sees of the ideal render ``img``: each observed pixel takes the
    ideal image at ``undistort(pixel)`` (bicubic on the float image, then 12-bit rounding)."""
    rr, cc = np.mgrid[0 : cam.rows, 0 : cam.cols]
    ideal = cam.undistort(np.stack([rr.ravel(), cc.ravel()], axis=1).astype(float))
    out = cv2.remap(np.asarray(img, np.float32), ideal[:, 1].reshape(rr.shape).astype(np.float32),
                    ideal[:, 0].reshape(rr.shape).astype(np.float32), cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    return np.clip(np.rint(out), 0, 4095).astype(np.uint16)


def test_undistort_image_inverts_the_warp():
    cam = Camera(focal_length_mm=8.0, rows=120, cols=160, k1=-0.02, k2=0.003, p1=1e-4)
    yy, xx = np.mgrid[0:120, 0:160]
    smooth = (np.sin(yy / 9.0) + np.cos(xx / 11.0)) * 1000 + 2000
    back = undistort_image(_distorted_frame(smooth, cam), cam)
    inner = (slice(10, 110), slice(10, 150))
    assert np.abs(back[inner] - smooth[inner]).max() < 20  # 1 % of the amplitude: interpolation only


def test_earth_with_a_distorted_camera():
    # a wide 4 mm camera with barrel distortion: the limb moves by ~2 px, the centre by ~0.1 px
    cam = Camera(focal_length_mm=4.0, rows=800, cols=800, k1=-0.2, k2=0.05)
    pin = pinhole_of(cam)
    sc = earth_scene(50000.0, 30.0, 40.0, center_rc=(470.3, 330.6), camera=pin, sun_angle_deg=30.0, north_angle_deg=80.0)
    img, truth = render_body(sc, pin, RenderOptions(), seed=3)
    frame = _distorted_frame(img, cam)
    hints = {"body": "earth", "range_prior_km": 1.01 * truth.range_km, "sun_dir_camera": list(truth.sun_dir_cam),
             "R_body_to_camera": np.asarray(sc.R_body_to_camera).tolist()}
    m = locate(frame, cam, hints)
    c_obs = cam.distort(np.asarray(truth.center_rc, float))
    assert np.hypot(*np.subtract(m.center_rc, c_obs)) <= 0.05
    assert abs(m.range_km / truth.range_km - 1.0) <= 1e-3
    assert np.allclose(m.los_camera, cam.los(np.asarray(m.center_rc)), atol=1e-12)
    assert m.extras["undistorted_image"]
    s = np.sqrt(m.covariance["center_r"]["center_r"])
    assert 0.0 < s < 0.05
    # what the distortion does here (so that the test means something)
    limb = np.asarray(truth.center_rc) + np.array([0.0, -1.0]) * truth.apparent_radius_px
    assert np.hypot(*(cam.distort(limb) - limb)) > 1.0
