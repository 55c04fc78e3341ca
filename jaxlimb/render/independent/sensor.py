r"""Sensor model of the independent renderer: exposure, stars, photon and read noise,
quantisation to 8 or 12 bits (12-bit values in ``uint16``), hot pixels, JPEG.

Exposure: the brightest pixel of the blurred radiance reaches ``level`` of the full well
(20 000 e-).  Signal in electrons ``S = k L + background``, photon noise Poisson(``S``), read
noise Gaussian (``read_noise_dn`` DN rms), gain ``full_well / (2^bits - 1)`` e-/DN, rounded
and clipped to ``[0, 2^bits - 1]``.  Stars (before the noise): point sources of flux
log-uniform in ``star_flux_dn`` (DN), drawn with a Gaussian of 0.8 px integrated over each pixel
(erf), outside the body's window.  Hot pixels (after the noise): single pixels raised by
30-100 % of full scale anywhere.  JPEG: ``cv2.imencode`` at ``quality`` (8-bit only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import erf

FULL_WELL_E = 20000.0


@dataclass(frozen=True)
class SensorSpec:
    bits: int = 8
    read_noise_dn: float = 2.0
    background_dn: float = 3.0
    level: float = 0.8
    n_stars: int = 0
    star_flux_dn: tuple[float, float] = (50.0, 3000.0)
    n_hot: int = 0
    jpeg_quality: int | None = None


def _add_stars(img_dn: np.ndarray, rng: np.random.Generator, spec: SensorSpec, avoid: tuple) -> None:
    r0, r1, c0, c1 = avoid
    rows, cols = img_dn.shape
    n_done = 0
    while n_done < spec.n_stars:
        r, c = rng.uniform(3, rows - 4), rng.uniform(3, cols - 4)
        if r0 - 5 <= r <= r1 + 5 and c0 - 5 <= c <= c1 + 5:
            continue
        lo, hi = np.log(spec.star_flux_dn[0]), np.log(spec.star_flux_dn[1])
        flux = float(np.exp(rng.uniform(lo, hi)))
        ir, ic = int(r), int(c)
        edges_r = np.arange(ir - 3, ir + 5) - 0.5 - r
        edges_c = np.arange(ic - 3, ic + 5) - 0.5 - c
        s = 0.8 * np.sqrt(2.0)
        pr = np.diff(0.5 * erf(edges_r / s))
        pc = np.diff(0.5 * erf(edges_c / s))
        img_dn[ir - 3: ir + 4, ic - 3: ic + 4] += flux * np.outer(pr, pc)
        n_done += 1


def digitise(radiance: np.ndarray, spec: SensorSpec, rng: np.random.Generator, window: tuple) -> np.ndarray:
    """Radiance image -> integer image (module docstring)."""
    top = 2**spec.bits - 1
    gain = FULL_WELL_E / top
    peak = float(np.max(radiance))
    k = spec.level * FULL_WELL_E / peak if peak > 0 else 0.0
    sig_dn = radiance * (k / gain) + spec.background_dn
    if spec.n_stars:
        _add_stars(sig_dn, rng, spec, window)
    e = rng.poisson(np.maximum(sig_dn, 0.0) * gain).astype(float)
    dn = e / gain + rng.normal(0.0, spec.read_noise_dn, e.shape)
    for _ in range(spec.n_hot):
        r, c = rng.integers(0, dn.shape[0]), rng.integers(0, dn.shape[1])
        dn[r, c] += rng.uniform(0.3, 1.0) * top
    out = np.clip(np.rint(dn), 0, top).astype(np.uint8 if spec.bits <= 8 else np.uint16)
    if spec.jpeg_quality is not None:
        out = jpeg(out, spec.jpeg_quality)
    return out


def jpeg(img8: np.ndarray, quality: int) -> np.ndarray:
    """Round trip through JPEG at ``quality`` (8-bit grey)."""
    import cv2

    if img8.dtype != np.uint8:
        raise ValueError("JPEG needs an 8-bit image")
    ok, buf = cv2.imencode(".jpg", img8, [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)])
    if not ok:  # pragma: no cover
        raise RuntimeError("cv2.imencode failed")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
