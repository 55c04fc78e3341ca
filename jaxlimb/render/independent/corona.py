r"""The Sun in the extreme ultraviolet for the independent renderer: an optically thin corona over an opaque disc.

Written apart from :mod:`jaxlimb.models.corona` and with other physics: the emission of each pixel is the integral
along its line of sight (sub-sampled pixels, exact spherical geometry, no ``a >> h`` expansion) of an emissivity
:math:`\epsilon = \sum_k w_k n_k^2` of three hydrostatic components in a gravity falling as :math:`1/\rho^2`,
:math:`n_k = \exp(-(R_o / H_k)(1 - R_o/\rho))` (the scale height grows with height), times active regions: bright
patches at random places on the sphere, front, limb and back (Gaussian in angle, 3-15 deg across, 0.5-4 times the
quiet level).  The line of sight stops at the occulting sphere :math:`R_o`, a little above the photosphere ``R``
(the truth's radius: the top of the chromosphere, 0.2-1 % of ``R``).  Blur: a Gaussian PSF (0.4-1.2 px) with a
wide wing of scattered light (2-5 % of the light in a Gaussian of 6-12 px); Poisson and read noise, 14 bits.
Aschwanden 2005, *Physics of the Solar Corona*, sec. 3.1 (hydrostatic corona, EUV emission measure ``n^2``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

#: Sub-samples per pixel side.
_SUB = 3
#: Samples along each line of sight per smallest scale height.
_PER_H = 6


@dataclass(frozen=True)
class EuvSun:
    """One rendered EUV Sun: the image (DN), the photosphere's centre ``(row, col)`` and radius (px)."""

    image: np.ndarray
    center_rc: tuple[float, float]
    radius_px: float


def _regions(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = int(rng.integers(3, 9))
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True), np.radians(rng.uniform(1.5, 7.5, n)), rng.uniform(0.5, 4.0, n)


def _emissivity(x, y, z, Ro, comps, regions):  # noqa: ANN001, ANN202
    rho = np.sqrt(x * x + y * y + z * z)
    q = 1.0 - Ro / np.maximum(rho, Ro)
    eps = sum(w * np.exp(-2.0 * (Ro / H) * q) for w, H in comps)
    dirs, widths, amps = regions
    u = np.stack(np.broadcast_arrays(x, y, z), -1) / rho[..., None]
    boost = 1.0 + sum(a * np.exp(-0.5 * (np.arccos(np.clip(u @ d, -1, 1)) / w) ** 2)
                      for d, w, a in zip(dirs, widths, amps))
    return np.where(rho >= Ro, eps * boost, 0.0)


def _column(px, py, Ro, comps, regions, zmax, dz):  # noqa: ANN001, ANN202
    """The emission along the lines of sight through ``(px, py)`` (observer at ``+z``), stopped by the occulter: a
    midpoint rule on segments growing by 2 % from the occulter (on the disc) or the tangent point (off it)."""
    b2 = px * px + py * py
    on = b2 < Ro * Ro
    zs = np.where(on, np.sqrt(np.maximum(Ro * Ro - b2, 0.0)), 0.0)[..., None]
    k = np.arange(int(math.log(1.0 + zmax * 0.02 / dz) / math.log(1.02)) + 2)
    t = dz * (1.02**k - 1.0) / 0.02
    m, w = 0.5 * (t[1:] + t[:-1]), np.diff(t)
    total = 0.0
    for sign, weight in ((1.0, 1.0), (-1.0, np.where(on, 0.0, 1.0)[..., None])):
        z = zs + sign * m
        e = _emissivity(px[..., None], py[..., None], z, Ro, comps, regions)
        total = total + np.sum(weight * e * w, -1)
    return total


def euv_sun(rng: np.random.Generator, radius_px: float = 50.0, size: int = 128) -> EuvSun:
    """Render one EUV Sun of photospheric radius ``radius_px`` in a ``size x size`` frame (module docstring)."""
    R = float(radius_px)
    Ro = R * (1.0 + rng.uniform(0.002, 0.01))
    H1 = R * rng.uniform(0.04, 0.09)
    comps = ((1.0, H1), (rng.uniform(0.2, 0.6), H1 * rng.uniform(1.5, 2.5)), (rng.uniform(0.5, 2.0), R * 0.01))
    regions = _regions(rng)
    c = (size - 1) / 2.0 + rng.uniform(-0.1, 0.1, 2) * size
    zmax = Ro + 12.0 * H1 * 2.5
    dz = min(h for _, h in comps) / _PER_H
    sub = (np.arange(_SUB) + 0.5) / _SUB - 0.5
    img = np.zeros((size, size))
    rows = np.arange(size)
    for i in range(size):  # one row of pixels at a time
        rr = (i + sub)[:, None, None] - c[0]
        cc = (rows[None, :, None] + sub[None, None, :]) - c[1]
        px, py = np.broadcast_arrays(cc, rr)
        img[i] = _column(px, py, Ro, comps, regions, zmax, dz).mean(axis=(0, 2))
    sigma, wing, wing_sigma = rng.uniform(0.4, 1.2), rng.uniform(0.02, 0.05), rng.uniform(6.0, 12.0)
    img = (1 - wing) * cv2.GaussianBlur(img, (0, 0), sigma) + wing * cv2.GaussianBlur(img, (0, 0), wing_sigma)
    electrons = rng.poisson(img * (12000.0 / img.max()) + 20.0) + rng.normal(0.0, 4.0, img.shape)
    dn = np.clip(np.round(electrons / 2.0), 0, 2**14 - 1)
    return EuvSun(dn, (float(c[0]), float(c[1])), R)


__all__ = ["EuvSun", "euv_sun"]
