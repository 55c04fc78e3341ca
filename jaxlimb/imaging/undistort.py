"""Resample a lens-distorted frame onto the ideal (pinhole) pixel grid of its camera.

The Earth pipeline fits the limb as a conic, which it is only in an ideal image; rather than
refuse a Brown-Conrady camera (:class:`jaxlimb.geometry.camera.Camera`), it measures in the
ideal image and maps the answer back.  Each ideal pixel ``(r, c)`` takes the value of the
observed image at ``camera.distort((r, c))`` (bicubic, OpenCV ``remap``); the interpolation is a
small extra blur that the limb fits absorb into their edge width (bilinear moved a 40 000 km
Earth's centre by 0.07 px in ``tests/pipeline_earth/test_earth_distorted.py``, bicubic < 0.05).
"""

from __future__ import annotations

import cv2
import numpy as np

from ..geometry.camera import Camera

__all__ = ["pinhole_of", "undistort_image"]


def pinhole_of(camera: Camera) -> Camera:
    """The same camera without lens distortion."""
    return Camera(camera.focal_length_mm, camera.pixel_pitch_mm, camera.rows, camera.cols, camera.principal_point_rc)


def undistort_image(image: np.ndarray, camera: Camera) -> np.ndarray:
    """The ideal (pinhole) image of ``camera``'s distorted ``image`` (float32, same shape).

    Ideal pixels whose observed position falls outside the frame repeat the nearest border
    pixel (``BORDER_REPLICATE``: no artificial edge at the frame border).
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 3:
        img = img.mean(axis=2)
    rr, cc = np.mgrid[0 : camera.rows, 0 : camera.cols]
    obs = camera.distort(np.stack([rr.ravel(), cc.ravel()], axis=1).astype(float))
    map_r = obs[:, 0].reshape(rr.shape).astype(np.float32)
    map_c = obs[:, 1].reshape(rr.shape).astype(np.float32)
    return cv2.remap(img, map_c, map_r, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
