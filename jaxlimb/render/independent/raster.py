r"""Supersampled rendering of a sunlit ellipsoid through a PSF, block by block.

The pixel value is the radiance convolved with the PSF and the pixel's box, at the pixel
centre.  Two passes:

1. the whole body window at 2x2 samples per pixel, averaged (the box), then convolved with
   the PSF binned to pixels -- exact enough where the radiance is smooth (interior, sky);
2. every 32x32 block within ``band`` px of the limb is recomputed on a grid of ``s x s``
   samples per pixel (``s = 4``) over the block plus a halo of the PSF's extent, samples
   within 1.5 fine cells of the limb refined by a further 4x4 (effectively 16x16 per pixel
   at the edge), convolved with the PSF sampled on the same fine grid, the halo cropped and
   the samples averaged per pixel (the box).  Those blocks replace pass 1's values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import fftconvolve

from .geometry import Body, Pinhole, cast, limb_distance_px, limb_truth
from .optics import Glow, Psf, glow_column
from .surface import Photometry, UniformMap

_BLOCK = 32
_FINE = 4
_EDGE_SUB = 4


@dataclass(frozen=True, eq=False)
class Surface:
    """What the body looks like: reflectance law, albedo map (callable on unit body vectors), glow."""

    photometry: Photometry = field(default_factory=Photometry)
    albedo: object = field(default_factory=UniformMap)
    glow: Glow | None = None


def radiance(body: Body, surf: Surface, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Radiance along the rays through image points ``rows, cols`` (same shape)."""
    shape = np.shape(rows)
    pin_d = _PIN[0].directions(rows.ravel(), cols.ravel())
    h = cast(body, pin_d)
    out = np.zeros(h.rho.shape)
    if np.any(h.hit):
        u = h.x_body / np.sqrt(np.einsum("ij,ij->i", h.x_body, h.x_body))[:, None]
        out[h.hit] = surf.photometry.radiance(h.mu0, h.mu, h.cos_g) * surf.albedo(u)
    if surf.glow is not None:
        out += _glow(body, surf.glow, h)
    return out.reshape(shape)


def _glow(body: Body, glow: Glow, h) -> np.ndarray:
    r = np.asarray(body.radii, float)
    out = np.zeros(h.rho.shape)
    near = h.rho < 1.0 + 1.2 * glow.top_km / min(r)  # rays that pass through the shell
    if not np.any(near):
        return out
    o_b = body.observer_scaled * r
    db = h.d_body[near]
    xc = o_b + (-(db @ o_b))[:, None] * db  # closest approach point, km
    p = np.sqrt(np.einsum("ij,ij->i", xc, xc))
    R_l = p / np.linalg.norm(xc / r, axis=-1)
    mu = np.zeros(p.shape)
    mu[h.hit[near]] = h.mu[near[h.hit]]
    col = glow_column(glow, p, R_l, mu, h.hit[near])
    n = xc / (r * r)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    s_b = body.R_body_to_camera.T @ np.asarray(body.sun_dir_cam, float)
    lit = np.clip((n @ s_b + 0.2) / 0.4, 0.0, 1.0)
    out[near] = glow.brightness * lit * col / np.sqrt(2.0 * np.pi * R_l * glow.scale_height_km)
    return out


# the pinhole used by `radiance` (set by render_radiance; a module slot keeps the signature small)
_PIN: list[Pinhole] = [Pinhole(1.0, 1, 1, (0.0, 0.0))]


def _window(body: Body, pin: Pinhole, margin: int) -> tuple[int, int, int, int]:
    t = limb_truth(body, pin)
    (r, c), big = t.ellipse_center_rc, t.semi_axes_px[0]
    r0 = max(0, int(math.floor(r - big - margin)))
    r1 = min(pin.rows, int(math.ceil(r + big + margin)) + 1)
    c0 = max(0, int(math.floor(c - big - margin)))
    c1 = min(pin.cols, int(math.ceil(c + big + margin)) + 1)
    if r1 <= r0 or c1 <= c0:
        raise ValueError("the body is entirely outside the frame")
    return r0, r1, c0, c1


def _sample_grid(r0: int, r1: int, c0: int, c1: int, s: int) -> tuple[np.ndarray, np.ndarray]:
    off = (np.arange(s) + 0.5) / s - 0.5
    rr = (np.arange(r0, r1)[:, None] + off[None, :]).ravel()
    cc = (np.arange(c0, c1)[:, None] + off[None, :]).ravel()
    return np.meshgrid(rr, cc, indexing="ij")


def _bin(a: np.ndarray, s: int) -> np.ndarray:
    n, m = a.shape[0] // s, a.shape[1] // s
    return a.reshape(n, s, m, s).mean(axis=(1, 3))


def _fine_tile(body: Body, surf: Surface, pin: Pinhole, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """Radiance on the ``_FINE`` grid of pixels ``[r0, r1) x [c0, c1)``, edge cells refined."""
    R, C = _sample_grid(r0, r1, c0, c1, _FINE)
    out = radiance(body, surf, R, C)
    dist = limb_distance_px(body, pin, R, C)
    edge = np.abs(dist) < 1.5 / _FINE
    if np.any(edge):
        sub = ((np.arange(_EDGE_SUB) + 0.5) / _EDGE_SUB - 0.5) / _FINE
        dr, dc = np.meshgrid(sub, sub, indexing="ij")
        er = R[edge][:, None] + dr.ravel()[None, :]
        ec = C[edge][:, None] + dc.ravel()[None, :]
        out[edge] = radiance(body, surf, er, ec).mean(axis=1)
    return out


def render_radiance(body: Body, surf: Surface, pin: Pinhole, psf: Psf, band_px: float | None = None) -> np.ndarray:
    """The blurred, pixel-integrated radiance image ``(rows, cols)`` (module docstring)."""
    _PIN[0] = pin
    E = psf.extent_px()
    glow_px = 0.0 if surf.glow is None else surf.glow.top_km * pin.focal_px / body.range_km
    margin = int(math.ceil(E + min(glow_px, 60.0) + 4))
    r0, r1, c0, c1 = _window(body, pin, margin)
    img = np.zeros((pin.rows, pin.cols))
    R, C = _sample_grid(r0, r1, c0, c1, 2)
    coarse = _bin(radiance(body, surf, R, C), 2)
    kpix = pixel_kernel(psf)
    img[r0:r1, c0:c1] = fftconvolve(np.pad(coarse, E), kpix, mode="same")[E:-E, E:-E]
    band = band_px if band_px is not None else 6.0 + E + min(glow_px, 60.0)
    Kf = psf.kernel(_FINE)
    for br in range(r0, r1, _BLOCK):
        for bc in range(c0, c1, _BLOCK):
            be_r, be_c = min(br + _BLOCK, r1), min(bc + _BLOCK, c1)
            rr, cc = np.meshgrid(np.arange(br, be_r, 4.0), np.arange(bc, be_c, 4.0), indexing="ij")
            d = limb_distance_px(body, pin, rr, cc)
            if np.min(np.abs(d)) > band + 4.0:
                continue
            if not np.any(coarse[max(br - E - r0, 0): be_r + E - r0, max(bc - E - c0, 0): be_c + E - c0]):
                continue  # the unlit limb: nothing to blur
            tile = _fine_tile(body, surf, pin, br - E, be_r + E, bc - E, be_c + E)
            conv = fftconvolve(tile, Kf, mode="same")
            h = E * _FINE
            img[br:be_r, bc:be_c] = _bin(conv[h:-h, h:-h], _FINE)
    return img


def pixel_kernel(psf: Psf) -> np.ndarray:
    """The PSF convolved with the pixel box, sampled at whole-pixel offsets (for pass 1):
    the PSF averaged over 8x8 points of each pixel."""
    E = psf.extent_px()
    j = np.arange(-E, E + 1, dtype=float)
    sub = (np.arange(8) + 0.5) / 8.0 - 0.5
    X = j[None, :, None, None] + sub[None, None, None, :]
    Y = j[:, None, None, None] + sub[None, None, :, None]
    n = j.size
    K = psf._value(np.broadcast_to(X, (n, n, 8, 8)), np.broadcast_to(Y, (n, n, 8, 8))).mean(axis=(2, 3))
    return K / K.sum()
