r"""Few-pixel bodies for the independent renderer: a Moon-like sphere of apparent radius ~1-12 px in a small frame.

The same per-pixel supersampled ray casting as every other family (:func:`~jaxlimb.render.independent.raster
.render_radiance`), at a range where the Moon's radius is ``radius_px``: a camera of ``focal_px`` (default 2000 px)
and ``size x size`` pixels (default 128), the body centre anywhere at least 12 px inside the frame, the Sun at
``phase_deg`` toward a random image direction, a Gaussian PSF of sigma uniform in ``psf_sigma`` (default 0.6-1.2 px;
or the kind asked), a sensor of ``bits`` (8, 12 or 16) whose read noise sets the signal-to-noise ratio of the
brightest pixel (``snr``: peak signal over the noise there, photon and read noise together), on a sky level of
1500 e- (a bias: no sky pixel is clipped at 0).  Hints as a filter has them: the body, the Sun direction and a range
prior 5 % (1 sigma) off.  ``empty=True``: the same frame and hints without the body (sky and noise only).
"""

from __future__ import annotations

import math

import numpy as np

from ...geometry.camera import Camera
from .families import MOON_RADIUS_KM, Case, image_direction, random_rotation, sun_for_phase
from .geometry import Body, Pinhole, limb_truth
from .optics import Psf, PsfKind
from .raster import Surface, render_radiance
from .sensor import FULL_WELL_E, SensorSpec, digitise
from .surface import Photometry, Reflectance

#: Fraction of the full well the brightest pixel reaches (:func:`~jaxlimb.render.independent.sensor.digitise`).
_LEVEL = 0.8


#: The sky level (e-): a bias well above the read noise, so that no sky pixel is clipped at 0.
_SKY_E = 1500.0


def read_noise_for_snr(snr: float, bits: int = 12) -> float:
    """Read noise (DN) that gives the brightest pixel (at :data:`_LEVEL` of the full well, on the sky level) the
    ratio ``snr``."""
    peak_e = _LEVEL * FULL_WELL_E
    var_e = (peak_e / snr) ** 2 - peak_e - _SKY_E
    if var_e <= 0:
        raise ValueError(f"an SNR of {snr} exceeds the photon limit {math.sqrt(peak_e):.0f} of this sensor")
    return math.sqrt(var_e) / (FULL_WELL_E / (2**bits - 1))


def small_body_case(radius_px: float, phase_deg: float, rng: np.random.Generator, *, size: int = 128,
                    focal_px: float = 2000.0, snr: float = 60.0, law: Reflectance = Reflectance.LUNAR_LAMBERT,
                    psf_kind: PsfKind = PsfKind.GAUSSIAN, range_error_frac: float = 0.05, bits: int = 12,
                    psf_sigma: tuple[float, float] = (0.6, 1.2), empty: bool = False) -> Case:
    """A Moon-like sphere of apparent radius ``radius_px`` (module docstring)."""
    cam = Camera(focal_length_mm=focal_px * 0.0022, pixel_pitch_mm=0.0022, rows=size, cols=size)
    pin = Pinhole.from_camera(cam)
    rng_km = MOON_RADIUS_KM / math.sin(math.atan(radius_px / pin.focal_px))
    m = radius_px + 12.0
    rc = (float(rng.uniform(m, size - 1 - m)), float(rng.uniform(m, size - 1 - m)))
    u = pin.los(rc)
    sun_angle = float(rng.uniform(0.0, 360.0))
    s = sun_for_phase(u, image_direction(pin, u, sun_angle), phase_deg)
    body = Body((MOON_RADIUS_KM,) * 3, rng_km * u, random_rotation(rng), s)
    psf = Psf(kind=psf_kind, sigma=float(rng.uniform(*psf_sigma)), r_zero=float(rng.uniform(1.2, 2.0)),
              r_disc=float(rng.uniform(0.8, 1.8)), length=float(rng.uniform(1.5, 3.5)),
              angle_deg=float(rng.uniform(0, 180)))
    rad = render_radiance(body, Surface(Photometry(law=law)), pin, psf)
    top = 2**bits - 1
    spec = SensorSpec(bits=bits, read_noise_dn=read_noise_for_snr(snr, bits), background_dn=_SKY_E / (FULL_WELL_E / top),
                      level=_LEVEL)
    img = digitise(0.0 * rad if empty else rad, spec, rng, (0, 0, 0, 0))
    hints = {"body": "moon", "sun_dir_camera": [float(v) for v in s],
             "range_prior_km": rng_km * (1.0 + range_error_frac * float(rng.standard_normal()))}
    meta = {"family": "small", "radius_px": radius_px, "phase_deg": phase_deg, "sun_angle_deg": sun_angle,
            "snr": snr, "bits": bits, "empty": empty, "psf": psf.kind.value, "psf_sigma": psf.sigma, "law": law.value, "range_km": rng_km}
    return Case(img, limb_truth(body, pin), cam, hints, meta)


__all__ = ["read_noise_for_snr", "small_body_case"]
