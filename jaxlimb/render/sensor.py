r"""Sensor model of the truth renderer: PSF, stars, hot pixels, noise, quantisation.

Signal chain (all images in electrons until the last step):

1. radiance (unit: Lambert albedo-1 normal incidence = 1) x ``exposure_e`` -> electrons;
2. Gaussian PSF of standard deviation ``psf_sigma_px`` (:func:`gaussian_psf`; applied to the
   padded render window so that bodies cut by the frame are blurred correctly);
3. stars: point sources with the same PSF, drawn as the exact pixel integral of the Gaussian
   (:func:`add_point_sources`); stars behind the body are hidden;
4. + ``background_e`` (dark current / sky), Poisson photon noise (``photon_noise``);
5. hot pixels (+ a fixed number of electrons each);
6. clip at the full well (when quantising), + Gaussian read noise ``read_noise_e``;
7. / ``gain_e_per_dn`` + Gaussian ``extra_noise_dn`` (e.g. the 10 grey levels of the
   Aerospace 2015 Monte Carlo), round, clip to ``[0, 2^bits - 1]`` (saturation).

With ``bit_depth=None`` the output is the float image in DN, unclipped and unrounded.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erf

from ..errors import ConfigError

__all__ = ["add_point_sources", "digitise", "gaussian_psf", "psf_pad"]


def psf_pad(sigma_px: float) -> int:
    """Half-width (px) of the Gaussian kernel used for ``sigma_px``: ``ceil(4 sigma)``."""
    return 0 if sigma_px <= 0 else int(math.ceil(4.0 * sigma_px))


def gaussian_psf(img: np.ndarray, sigma_px: float) -> np.ndarray:
    """Blur with a normalised Gaussian (OpenCV, kernel half-width ``ceil(4 sigma)``), zero outside.

    Flux is conserved as long as no flux reaches the array border (render with a pad of
    :func:`psf_pad` and crop afterwards).
    """
    if sigma_px < 0 or not math.isfinite(sigma_px):
        raise ConfigError(f"`psf_sigma_px` must be finite and >= 0, got {sigma_px!r}")
    if sigma_px == 0 or img.size == 0:
        return img
    import cv2

    k = 2 * psf_pad(sigma_px) + 1
    return cv2.GaussianBlur(
        np.ascontiguousarray(img, dtype=np.float64), (k, k), sigmaX=sigma_px, sigmaY=sigma_px,
        borderType=cv2.BORDER_CONSTANT,
    )


def add_point_sources(img: np.ndarray, rc: np.ndarray, flux: np.ndarray, sigma_px: float) -> None:
    """Add point sources (in place) at ``rc`` ``(n, 2)`` with total ``flux`` each.

    Each source deposits the exact integral of a circular Gaussian of ``sigma_px`` over the
    pixel footprints ``[i-0.5, i+0.5] x [j-0.5, j+0.5]`` (separable erf differences); with
    ``sigma_px = 0`` all the flux goes to the pixel containing the point.
    """
    rows, cols = img.shape
    rc = np.asarray(rc, dtype=float).reshape(-1, 2)
    flux = np.asarray(flux, dtype=float).reshape(-1)
    if sigma_px <= 0:
        i = np.floor(rc[:, 0] + 0.5).astype(int)
        j = np.floor(rc[:, 1] + 0.5).astype(int)
        ok = (i >= 0) & (i < rows) & (j >= 0) & (j < cols)
        np.add.at(img, (i[ok], j[ok]), flux[ok])
        return
    w = psf_pad(sigma_px) + 1
    off = np.arange(-w, w + 1)
    s2 = math.sqrt(2.0) * sigma_px
    for (r, c), f in zip(rc, flux):
        ir, ic = int(round(r)), int(round(c))
        pr = ir + off
        pc = ic + off
        wr = 0.5 * (erf((pr + 0.5 - r) / s2) - erf((pr - 0.5 - r) / s2))
        wc = 0.5 * (erf((pc + 0.5 - c) / s2) - erf((pc - 0.5 - c) / s2))
        mr = (pr >= 0) & (pr < rows)
        mc = (pc >= 0) & (pc < cols)
        if not (np.any(mr) and np.any(mc)):
            continue
        img[np.ix_(pr[mr], pc[mc])] += f * np.outer(wr[mr], wc[mc])


def digitise(
    electrons: np.ndarray,
    rng: np.random.Generator,
    *,
    bit_depth: int | None,
    full_well_e: float,
    gain_e_per_dn: float,
    read_noise_e: float,
    extra_noise_dn: float,
    photon_noise: bool,
    hot_pixels: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Steps 4-7 of the module docstring (``electrons`` already includes the background)."""
    e = np.array(electrons, dtype=float)
    if photon_noise:
        e = rng.poisson(np.maximum(e, 0.0)).astype(float)
    if hot_pixels is not None:
        (idx, val) = hot_pixels
        e[idx[:, 0], idx[:, 1]] += val
    if bit_depth is not None:
        np.minimum(e, full_well_e, out=e)
    dn = e / gain_e_per_dn
    # read noise (e-) and extra noise (DN) are independent Gaussians: one draw of their sum
    sig = math.hypot(read_noise_e / gain_e_per_dn, extra_noise_dn)
    if sig > 0:
        dn += sig * rng.standard_normal(dn.shape, dtype=np.float32)
    if bit_depth is None:
        return dn
    top = 2**bit_depth - 1
    out = np.clip(np.rint(dn, out=dn), 0, top, out=dn)
    return out.astype(np.uint8 if bit_depth <= 8 else np.uint16)
