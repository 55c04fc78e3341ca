"""Rendered test scenes with exact truth, cached per process (the renders are the slow part)."""

from __future__ import annotations

import functools

import numpy as np

from jaxlimb.geometry.camera import Camera
from jaxlimb.imaging import Hints
from jaxlimb.render import RenderOptions, moon_scene, render_body

#: A 400x500 camera with the default camera's field of view scaled down (f = 1403 px).
SMALL_CAMERA = Camera(focal_length_mm=16.0 * 500 / 2592, rows=400, cols=500)
#: 8-bit frames, 2 DN read noise (full well / 255 e- per DN).
_READ_2DN = 2.0 * 20000.0 / 255.0


def render_options(reflectance: str = "lunar-lambert", psf: float = 1.0, **kw) -> RenderOptions:
    return RenderOptions(reflectance=reflectance, psf_sigma_px=psf, bit_depth=8, read_noise_e=_READ_2DN, **kw)


@functools.lru_cache(maxsize=64)
def scene(range_km: float, phase_deg: float, center_rc: tuple[float, float], sun_angle_deg: float = 30.0,
          reflectance: str = "lunar-lambert", psf: float = 1.0, seed: int = 1, camera: Camera = SMALL_CAMERA,
          n_stars: int = 0, n_hot: int = 0, exposure_scale: float = 1.0):
    """``(image, truth)`` of the Moon (cached); ``exposure_scale`` > 1 over-exposes (clips) it."""
    sc = moon_scene(range_km, phase_deg, center_rc=center_rc, camera=camera, sun_angle_deg=sun_angle_deg)
    opts = render_options(reflectance, psf, n_stars=n_stars, n_hot_pixels=n_hot)
    img, truth = render_body(sc, camera, opts, seed=seed)
    if exposure_scale != 1.0:
        opts = render_options(reflectance, psf, n_stars=n_stars, n_hot_pixels=n_hot,
                              exposure_e=truth.exposure_e * exposure_scale)
        img, truth = render_body(sc, camera, opts, seed=seed)
    img.setflags(write=False)
    return img, truth


def sun_hints(truth, **kw) -> Hints:
    """Hints a navigation filter would give: the Moon, the Sun direction (and anything in ``kw``)."""
    return Hints(body="moon", sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam), **kw)


def errors(meas, truth) -> tuple[float, float]:
    """(centre error, radius error) in px against the render's truth."""
    dc = float(np.hypot(meas.center_rc[0] - truth.center_rc[0], meas.center_rc[1] - truth.center_rc[1]))
    return dc, float(meas.radius_px - truth.apparent_radius_px)
