r"""Point-spread functions on a fine grid and an exponential glow above the limb.

PSFs (``Psf``; every kernel is sampled at the centres of a grid of spacing ``1/s`` px, each
cell averaged over 3x3 points, truncated and normalised to sum 1):

* ``GAUSSIAN`` ``sigma`` px;
* ``AIRY`` (diffraction by a circular aperture): :math:`(2J_1(x)/x)^2`, :math:`x = 3.8317\,r/r_z`
  with ``r_z`` the radius of the first dark ring (px), truncated at ``radius_px``;
* ``DEFOCUS``: a uniform disc of radius ``r_d`` px (geometric defocus);
* ``MOTION``: a Gaussian of ``sigma`` swept uniformly along a segment of ``length`` px at
  position angle ``angle`` (from ``+col`` toward ``-row``).

Glow (``Glow``): an optically thin shell whose emission per km falls as :math:`e^{-h/H}` with
the altitude :math:`h` above a sphere of the local radius :math:`R_l` of the body at the ray's
closest approach; the column along the ray is :func:`glow_column` (closed forms).  The radiance
is ``brightness`` times the column over the grazing column :math:`\sqrt{2\pi R_l H}`
(``brightness``: the glow just above the limb in units of a unit-albedo Lambert surface at
normal incidence), times the illumination of the shell at the closest approach,
:math:`\mathrm{clip}((n\cdot s + 0.2)/0.4, 0, 1)` (lit limb, fading past the terminator).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np
from scipy.special import j1


class PsfKind(str, Enum):
    GAUSSIAN = "gaussian"
    AIRY = "airy"
    DEFOCUS = "defocus"
    MOTION = "motion"


@dataclass(frozen=True)
class Psf:
    kind: PsfKind = PsfKind.GAUSSIAN
    sigma: float = 1.0
    r_zero: float = 1.6  # Airy first dark ring (px)
    r_disc: float = 1.5  # defocus disc radius (px)
    length: float = 2.5  # motion smear length (px)
    angle_deg: float = 30.0
    radius_px: int = 0  # truncation; 0 = automatic

    def extent_px(self) -> int:
        if self.radius_px:
            return int(self.radius_px)
        k = PsfKind(self.kind)
        if k is PsfKind.GAUSSIAN:
            return int(math.ceil(5.0 * self.sigma)) + 1
        if k is PsfKind.AIRY:
            return int(math.ceil(5.0 * self.r_zero)) + 1
        if k is PsfKind.DEFOCUS:
            return int(math.ceil(self.r_disc)) + 2
        return int(math.ceil(0.5 * self.length + 5.0 * self.sigma)) + 1

    def _value(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Unnormalised PSF at offsets ``x`` (col), ``y`` (row), px."""
        k = PsfKind(self.kind)
        if k is PsfKind.GAUSSIAN:
            return np.exp(-0.5 * (x * x + y * y) / self.sigma**2)
        if k is PsfKind.AIRY:
            z = 3.8317 * np.hypot(x, y) / self.r_zero
            zs = np.where(z > 1e-8, z, 1.0)
            return np.where(z > 1e-8, (2.0 * j1(zs) / zs) ** 2, 1.0)
        if k is PsfKind.DEFOCUS:
            return (np.hypot(x, y) <= self.r_disc).astype(float)
        a = math.radians(self.angle_deg)
        ex, ey = math.cos(a), -math.sin(a)
        out = np.zeros_like(x)
        for t in np.linspace(-0.5, 0.5, 41) * self.length:
            out += np.exp(-0.5 * ((x - t * ex) ** 2 + (y - t * ey) ** 2) / self.sigma**2)
        return out

    def kernel(self, s: int) -> np.ndarray:
        """The kernel on a grid of spacing ``1/s`` px, ``(2 s E + 1)`` square (``E`` = extent)."""
        E = self.extent_px()
        n = 2 * s * E + 1
        c = (np.arange(n) - s * E) / s
        sub = (np.arange(3) - 1.0) / (3.0 * s)  # 3x3 points per cell
        X = c[None, :, None, None] + sub[None, None, None, :]
        Y = c[:, None, None, None] + sub[None, None, :, None]
        K = self._value(np.broadcast_to(X, (n, n, 3, 3)), np.broadcast_to(Y, (n, n, 3, 3))).mean(axis=(2, 3))
        rr = np.hypot(c[None, :], c[:, None])
        K = np.where(rr <= E, K, 0.0)
        return K / K.sum()


@dataclass(frozen=True)
class Glow:
    """Exponential glow above the limb (module docstring): ``scale_height_km``, ``brightness``."""

    scale_height_km: float = 8.0
    brightness: float = 0.1

    @property
    def top_km(self) -> float:
        return 12.0 * self.scale_height_km


def glow_column(glow: Glow, p: np.ndarray, R_l: np.ndarray, mu_hit: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """Column :math:`\\int e^{-h/H} d\\sigma` (km) along rays through a spherical shell of radius ``R_l``.

    ``p`` closest-approach distance from the centre (km), ``mu_hit`` emission cosine of hits,
    ``hit`` mask.  A miss (both halves; :math:`\\sigma = p\\sinh t`):
    :math:`2\\,e^{-(p-R_l)/H}\\,p\\,K_1(p/H)\\,e^{p/H}` (exact).  A hit (the half in front of the
    surface), with :math:`h \\approx \\mu\\sigma + \\sigma^2/2R_l`:
    :math:`(H/\\mu)\\sqrt{\\pi/\\epsilon}\\,\\mathrm{erfcx}(1/\\sqrt{\\epsilon})`,
    :math:`\\epsilon = 2H/(R_l\\mu^2)` (:math:`H/\\mu` far from the limb,
    :math:`\\sqrt{\\pi R_l H/2}` at grazing)."""
    from scipy.special import erfcx, k1e

    H = glow.scale_height_km
    out = np.zeros_like(p)
    miss = ~hit
    pm = p[miss]
    out[miss] = 2.0 * np.exp(-(pm - R_l[miss]) / H) * pm * k1e(pm / H)
    mu = np.maximum(mu_hit[hit], 1e-9)
    eps = 2.0 * H / (R_l[hit] * mu * mu)
    out[hit] = H / mu * np.sqrt(np.pi / eps) * erfcx(1.0 / np.sqrt(eps))
    return out
