"""A close Moon near full phase on independent renders (:mod:`jaxlimb.render.independent`): each point of the disc
is seen at its own phase angle (``alpha0`` farther from the Sun from the limb on its side), and a phase law dims that
rim.  ``locate``'s profile gives each point the lunar-Lambert weight of its own phase angle
(:mod:`jaxlimb.models.lunar_lambert`): a lunar-Lambert Moon is measured without a displacement along the Sun.
Hapke's phase function falls faster than the lunar-Lambert weight; what the weight leaves, the refit under the
albedo field takes as a field (:func:`jaxlimb.pipeline.profile.albedo_field.with_albedo_field`;
``benchmarks/phase_across_disc.py``)."""

from __future__ import annotations

import math

import numpy as np

from jaxlimb.geometry.camera import Camera
from jaxlimb.imaging import Hints
from jaxlimb.pipeline import locate
from jaxlimb.render.independent import (Body, Photometry, Pinhole, Psf, PsfKind, Reflectance, SensorSpec, Surface,
                                        digitise, render_radiance)

RANGE_KM, MOON_KM, PHASE_DEG, F_PX, SIZE = 40_000.0, 1737.4, 5.0, 1000.0, 256


def _along_sun_error(photometry: Photometry, seed: int) -> float:
    """``locate``'s centre error along the Sun's image direction (+col; px) on a boresight Moon."""
    ph = math.radians(PHASE_DEG)
    sun = (math.sin(ph), 0.0, -math.cos(ph))  # camera frame: the Sun behind the observer, toward +x (+col)
    cam = Camera(focal_length_mm=F_PX * 0.0022, pixel_pitch_mm=0.0022, rows=SIZE, cols=SIZE,
                 principal_point_rc=(127.5, 127.5))
    body = Body((MOON_KM,) * 3, np.array([0.0, 0.0, RANGE_KM]), np.eye(3), np.array(sun))
    rad = render_radiance(body, Surface(photometry), Pinhole.from_camera(cam), Psf(PsfKind.GAUSSIAN, 0.8))
    spec = SensorSpec(bits=12, read_noise_dn=157.0 / (20000.0 / 4095), background_dn=40.0 / (20000.0 / 4095))
    img = digitise(rad * (3000.0 / rad.max()), spec, np.random.default_rng(seed), (0, SIZE - 1, 0, SIZE - 1))
    m = locate(img, cam, Hints(body="moon", sun_dir_camera=sun, range_prior_km=RANGE_KM))
    return float(m.center_rc[1] - 127.5)


def test_a_close_lunar_lambert_moon_is_not_displaced_by_the_phase_across_its_disc():
    err = _along_sun_error(Photometry(law=Reflectance.LUNAR_LAMBERT), 3)
    assert abs(err) < 0.012, err


def test_a_close_hapke_moon_is_not_displaced_by_the_phase_across_its_disc():
    err = _along_sun_error(Photometry(law=Reflectance.HAPKE), 3)
    assert abs(err) < 0.012, err
