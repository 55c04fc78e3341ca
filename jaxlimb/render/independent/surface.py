r"""Reflectance laws and albedo maps of the independent renderer.

Reflectance (radiance factor, before the albedo; :math:`\mu_0, \mu` the incidence and emission
cosines, :math:`g` the phase angle at the surface point; 0 where :math:`\mu_0 \le 0`):

* ``LUNAR_LAMBERT`` (McEwen 1996): :math:`L(g)\,2\mu_0/(\mu_0+\mu) + (1-L(g))\mu_0`,
  :math:`L = 1 - 0.019g + 2.42\cdot10^{-4}g^2 - 1.46\cdot10^{-6}g^3` (``g`` in degrees): the law
  the pipeline's limb profile assumes (the "own" family);
* ``LAMBERT``: :math:`\mu_0`;
* ``MINNAERT`` (Minnaert 1941): :math:`\mu_0^k\mu^{k-1}` (``k < 1``: a bright rim at the limb);
* ``LOMMEL_SEELIGER_SURGE``: :math:`\mu_0/(\mu_0+\mu)\,(1 + B(g))`, shadow-hiding opposition
  surge :math:`B(g) = B_0/(1 + \tan(g/2)/h)` (Hapke 1986, Eq. 11);
* ``HAPKE`` (Hapke 1981, isotropic multiple scattering approximation, no macroscopic roughness):
  :math:`\frac{w}{4}\frac{\mu_0}{\mu_0+\mu}\big[(1+B(g))P(g) + H(\mu_0)H(\mu) - 1\big]`,
  :math:`H(x) = (1+2x)/(1+2x\sqrt{1-w})` (Hapke 1981, Eq. 49), Henyey--Greenstein
  :math:`P(g) = (1-b^2)/(1 - 2b\cos g + b^2)^{3/2}` (back-scattering for ``b > 0``).

Albedo maps are functions of the body-fixed unit direction: ``MariaMap`` (smooth dark caps,
the lunar maria: depth 15-35 % below the highlands, 9-26 deg across), ``SpotsMap`` (overlapping
Gaussian spots over the whole body and a large-scale gradient: the albedo varies everywhere, across
the limb as well as along it), ``EarthMap`` (oceans, continents and clouds from 3-D value noise:
bright, textured, with features crossing the limb).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np


class Reflectance(str, Enum):
    LUNAR_LAMBERT = "lunar-lambert"
    LAMBERT = "lambert"
    MINNAERT = "minnaert"
    LOMMEL_SEELIGER_SURGE = "lommel-seeliger-surge"
    HAPKE = "hapke"


@dataclass(frozen=True)
class Photometry:
    """A reflectance law and its parameters (module docstring)."""

    law: Reflectance = Reflectance.LUNAR_LAMBERT
    minnaert_k: float = 0.7
    w: float = 0.25  # Hapke single-scattering albedo
    b: float = 0.25  # Henyey-Greenstein asymmetry (> 0: back-scattering)
    B0: float = 1.0  # opposition surge amplitude
    h: float = 0.06  # opposition surge width

    def radiance(self, mu0: np.ndarray, mu: np.ndarray, cos_g: np.ndarray) -> np.ndarray:
        lit = mu0 > 0
        m0 = np.where(lit, mu0, 0.0)
        m = np.clip(mu, 1e-6, 1.0)
        g = np.arccos(np.clip(cos_g, -1.0, 1.0))
        law = Reflectance(self.law)
        if law is Reflectance.LAMBERT:
            out = m0
        elif law is Reflectance.LUNAR_LAMBERT:
            gd = np.degrees(g)
            L = np.clip(1.0 - 0.019 * gd + 2.42e-4 * gd**2 - 1.46e-6 * gd**3, 0.0, 1.0)
            out = L * 2.0 * m0 / (m0 + m) + (1.0 - L) * m0
        elif law is Reflectance.MINNAERT:
            out = m0**self.minnaert_k * np.maximum(m, 1e-4) ** (self.minnaert_k - 1.0)
        elif law is Reflectance.LOMMEL_SEELIGER_SURGE:
            out = 2.0 * m0 / (m0 + m) * (1.0 + self._surge(g)) / (1.0 + self.B0)
        else:
            out = self._hapke(m0, m, g)
        return np.where(lit, out, 0.0)

    def _surge(self, g: np.ndarray) -> np.ndarray:
        return self.B0 / (1.0 + np.tan(0.5 * g) / self.h)

    def _hapke(self, m0: np.ndarray, m: np.ndarray, g: np.ndarray) -> np.ndarray:
        gam = math.sqrt(1.0 - self.w)

        def H(x):
            return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * gam)

        P = (1.0 - self.b**2) / (1.0 - 2.0 * self.b * np.cos(g) + self.b**2) ** 1.5
        return self.w / 4.0 * m0 / (m0 + m) * ((1.0 + self._surge(g)) * P + H(m0) * H(m) - 1.0) * 4.0


# ----------------------------------------------------------------------------- albedo maps
class UniformMap:
    """Albedo 1 everywhere."""

    def __call__(self, u: np.ndarray) -> np.ndarray:
        return np.ones(u.shape[:-1])


@dataclass(frozen=True, eq=False)
class MariaMap:
    """Smooth dark caps on a unit-albedo highland: ``1 - depth * taper(angle / radius)``.

    ``centers`` ``(n, 3)`` body-fixed unit vectors, ``radii_deg`` the cap radii (half the
    diameter), ``depths`` in (0, 1).  The taper is 1 inside 60 % of the radius and falls to 0 at
    the radius as a raised cosine (a smooth mare edge, no step)."""

    centers: np.ndarray
    radii_deg: np.ndarray
    depths: np.ndarray

    def __call__(self, u: np.ndarray) -> np.ndarray:
        cosang = np.clip(u @ np.asarray(self.centers, float).T, -1.0, 1.0)  # (n, k)
        ang = np.arccos(cosang) / np.radians(np.asarray(self.radii_deg, float))
        x = np.clip((ang - 0.6) / 0.4, 0.0, 1.0)
        taper = 0.5 * (1.0 + np.cos(np.pi * x))
        dark = np.clip(taper * np.asarray(self.depths, float), 0.0, None)
        return 1.0 - np.max(dark, axis=-1)


@dataclass(frozen=True, eq=False)
class SpotsMap:
    """Overlapping smooth spots with Gaussian profiles over the whole body, times a linear gradient.

    ``albedo(u) = (1 + gradient . u) * prod_k (1 - depth_k exp(-angle_k^2 / (2 s_k^2)))`` with
    ``angle_k`` the angle from spot ``k``'s centre and ``s_k = fwhm_k / 2.3548``: no flat plateau anywhere,
    so the albedo changes across a limb window as well as along the limb."""

    centers: np.ndarray
    fwhm_deg: np.ndarray
    depths: np.ndarray
    gradient: np.ndarray

    @classmethod
    def draw(cls, rng: np.random.Generator, n: int = 80, fwhm_deg: tuple[float, float] = (9.0, 26.0),
             depth: tuple[float, float] = (0.15, 0.35), gradient: float = 0.04) -> "SpotsMap":
        """``n`` spots with uniform centres on the sphere, FWHM and depth uniform in the given ranges, and a
        gradient of amplitude ``gradient`` along a uniform direction."""
        c = rng.normal(size=(n, 3))
        g = rng.normal(size=3)
        return cls(c / np.linalg.norm(c, axis=1, keepdims=True), rng.uniform(*fwhm_deg, n), rng.uniform(*depth, n),
                   gradient * g / np.linalg.norm(g))

    def __call__(self, u: np.ndarray) -> np.ndarray:
        un = u / np.linalg.norm(u, axis=-1, keepdims=True)
        flat = un.reshape(-1, 3)
        s = np.radians(np.asarray(self.fwhm_deg, float)) / 2.3548
        cosang = flat @ np.asarray(self.centers, float).T  # (m, n)
        spots = np.ones(flat.shape[0])
        for k in range(cosang.shape[1]):  # only where a spot reaches (beyond 6 s its dip is below 2e-8)
            near = np.nonzero(cosang[:, k] > math.cos(min(6.0 * s[k], math.pi)))[0]
            ang = np.arccos(np.clip(cosang[near, k], -1.0, 1.0))
            spots[near] *= 1.0 - self.depths[k] * np.exp(-0.5 * (ang / s[k]) ** 2)
        return ((1.0 + flat @ np.asarray(self.gradient, float)) * spots).reshape(un.shape[:-1])


@dataclass(frozen=True, eq=False)
class ValueNoise:
    """3-D value noise (random values on the integer lattice, quintic-smoothed trilinear
    interpolation, Perlin 2002) summed over octaves: smooth, band-limited, seeded."""

    seed: int = 0
    octaves: int = 5
    base_frequency: float = 3.0
    gain: float = 0.55
    _tables: tuple = field(default=None, repr=False)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        object.__setattr__(self, "_tables", (rng.permutation(256), rng.uniform(-1.0, 1.0, 256)))

    def _octave(self, p: np.ndarray) -> np.ndarray:
        perm, vals = self._tables
        i = np.floor(p).astype(np.int64)
        f = p - i
        w = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
        out = np.zeros(p.shape[:-1])
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    hsh = perm[(perm[(perm[(i[..., 0] + dx) & 255] + i[..., 1] + dy) & 255] + i[..., 2] + dz) & 255]
                    wt = ((w[..., 0] if dx else 1.0 - w[..., 0]) * (w[..., 1] if dy else 1.0 - w[..., 1])
                          * (w[..., 2] if dz else 1.0 - w[..., 2]))
                    out += wt * vals[hsh]
        return out

    def __call__(self, u: np.ndarray) -> np.ndarray:
        total = np.zeros(u.shape[:-1])
        amp, freq, norm = 1.0, self.base_frequency, 0.0
        for k in range(self.octaves):
            total += amp * self._octave(u * freq + 17.3 * (k + 1))
            norm += amp
            amp *= self.gain
            freq *= 2.0
        return total / norm


_TEX: dict = {}


@dataclass(frozen=True, eq=False)
class EarthMap:
    """Ocean (``ocean``), continents (``land``) and clouds (up to ``cloud``) from value noise.

    Land where a low-frequency noise exceeds ``land_threshold`` (soft 0.05 transition); cloud
    cover ``clip((n_c - cloud_threshold) / 0.25, 0, 1)`` of a 6-octave noise; albedo
    ``surface (1 - cover) + cloud cover``."""

    seed: int = 0
    ocean: float = 0.06
    land: float = 0.22
    cloud: float = 0.75
    land_threshold: float = 0.05
    cloud_threshold: float = 0.0

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """Bilinear look-up in a 1024 x 512 longitude/latitude texture of :meth:`exact` (0.35 deg
        texels; the finest cloud octave has a 2.8 deg wavelength)."""
        from scipy.ndimage import map_coordinates

        tex = self._texture()
        nlat, nlon = tex.shape
        lon = np.arctan2(u[..., 1], u[..., 0])
        lat = np.arcsin(np.clip(u[..., 2] / np.linalg.norm(u, axis=-1), -1.0, 1.0))
        x = (lon + np.pi) / (2 * np.pi) * (nlon - 1)
        y = (lat + np.pi / 2) / np.pi * (nlat - 1)
        return map_coordinates(tex, [y.ravel(), x.ravel()], order=1, mode="nearest").reshape(lon.shape)

    def _texture(self) -> np.ndarray:
        key = (self.seed, self.ocean, self.land, self.cloud, self.land_threshold, self.cloud_threshold)
        if key not in _TEX:
            lat = np.linspace(-np.pi / 2, np.pi / 2, 512)
            lon = np.linspace(-np.pi, np.pi, 1024)
            LA, LO = np.meshgrid(lat, lon, indexing="ij")
            u = np.stack([np.cos(LA) * np.cos(LO), np.cos(LA) * np.sin(LO), np.sin(LA)], axis=-1)
            if len(_TEX) > 4:
                _TEX.clear()
            _TEX[key] = self.exact(u)
        return _TEX[key]

    def exact(self, u: np.ndarray) -> np.ndarray:
        """The albedo at body-fixed unit vectors ``u`` (class docstring)."""
        n_land = ValueNoise(self.seed, 4, 1.5, 0.5)(u)
        n_cloud = ValueNoise(self.seed + 1, 6, 4.0, 0.6)(u)
        land = np.clip((n_land - self.land_threshold) / 0.05, 0.0, 1.0)
        surface = self.ocean + (self.land - self.ocean) * land
        cover = np.clip((n_cloud - self.cloud_threshold) / 0.25, 0.0, 1.0)
        return surface * (1.0 - cover) + self.cloud * cover
