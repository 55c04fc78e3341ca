"""A uniform disc's shading along traced rays (lunar-Lambert, blurred by the PSF and the pixel): the model that
flattens a dark limb's rays for the trace's flatness test and removes the crossings' photometric bias."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


SHADE_FINE = 0.05
"""The fine grid (px) on which :func:`shading_offsets` blurs its shading model."""


def limb_normals(cam, ell: tuple, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per ray angle: the outward surface normal at the limb ``n0`` (camera frame, perpendicular to the line of sight)
    and the unit vector ``v`` toward the observer from the centre of ellipse ``ell`` (a sphere's limb).

    Parameters
    ----------
    cam : Camera
        The pinhole camera.
    ell : tuple
        The limb ellipse ``((r0, c0), (a, b), theta)`` (px, rad); only its centre is used.
    angles : np.ndarray (n,)
        Ray angles ``atan2(d_row, d_col)`` (rad) about the centre.

    Returns
    -------
    n0 : np.ndarray (n, 3)
        Unit outward normals at the limb (camera frame).
    v : np.ndarray (3,)
        Unit vector from the body toward the observer (camera frame).
    """
    c = np.asarray(ell[0], float)
    v = -np.asarray(cam.los(c), float)
    u = np.column_stack([np.sin(angles), np.cos(angles)])
    d3 = np.asarray(cam.los(c[None, :] + 5.0 * u), float) + v[None, :]  # each ray's image direction in 3-D
    n0 = d3 - (d3 @ v)[:, None] * v[None, :]
    return n0 / np.linalg.norm(n0, axis=1, keepdims=True), v


def pixel_blur(psf_sigma_px: float) -> float:
    """The Gaussian sigma (px) of a PSF of ``psf_sigma_px`` sampled by square pixels (variance + 1/12).

    Parameters
    ----------
    psf_sigma_px : float
        The PSF's Gaussian sigma (px).

    Returns
    -------
    float
        ``sqrt(psf_sigma_px^2 + 1/12)`` (px).
    """
    return math.hypot(psf_sigma_px, math.sqrt(1.0 / 12.0))


def shaded_rows(normals: tuple, sun_dir_camera, R: float, sigma: float, L: float, xs: np.ndarray) -> np.ndarray:
    """Rows of a uniform disc's radiance sampled at ``xs`` on the rays of ``normals``: lunar-Lambert shading
    ``2L mu0/(mu0 + mu) + (1 - L) mu0`` on a sphere of radius ``R`` px, zero outside the limb, blurred by a Gaussian
    of ``sigma`` px on a grid of :data:`SHADE_FINE` px.

    Parameters
    ----------
    normals : tuple
        ``(n0, v)`` of :func:`limb_normals`.
    sun_dir_camera : array_like (3,)
        Direction toward the Sun (camera frame, any length).
    R : float
        The disc's radius (px).
    sigma : float
        The blur's Gaussian sigma (px).
    L : float
        The lunar-Lambert weight (0: Lambert).
    xs : np.ndarray (m,)
        Sample positions (px, outward from the limb; negative inside), increasing.

    Returns
    -------
    np.ndarray (n, m)
        The radiance (the Sun's unit irradiance) per ray and sample.
    """
    from scipy.ndimage import gaussian_filter1d

    n0, v = normals
    sun = np.asarray(sun_dir_camera, float) / np.linalg.norm(sun_dir_camera)
    xf = np.arange(xs[0] - 4.0 * sigma - 2.0, xs[-1] + 4.0 * sigma + 2.0, SHADE_FINE)
    th = np.arccos(np.clip(1.0 - np.clip(-xf, 0.0, None) / R, -1.0, 1.0))  # the normal's tilt toward the observer
    n = n0[:, None, :] * np.cos(th)[None, :, None] + v[None, None, :] * np.sin(th)[None, :, None]
    mu0, mu = np.clip(n @ sun, 0.0, None), np.sin(th)[None, :]
    shade = np.where(xf[None, :] <= 0.0, 2.0 * L * mu0 / np.maximum(mu0 + mu, 1e-9) + (1.0 - L) * mu0, 0.0)
    prof = gaussian_filter1d(shade, sigma / SHADE_FINE, axis=1, mode="nearest")
    return np.array([np.interp(xs, xf, p) for p in prof])


@dataclass(frozen=True)
class RayShading:
    r"""A uniform disc's shading along the rays, for :func:`trace_limb`'s flatness test (step 3) on a dark limb.

    Why: near zero phase a Lambert limb is dark and its radiance rises inward as ``sqrt(2u/R)`` (``mu0 ~ mu`` at depth
    ``u``), so the 2-5 px window inside the foot spans a factor ~1.6 and fails the flatness test on every ray of a
    uniform disc: a mottled limb is then not recognised as patchy, and the one-albedo profile answers far off
    (``docs/validation/constants.md#glow-and-shading``).  Divided by the shading a uniform ray is flat again, and a
    cloud edge inside the window is not.  The model is
    :func:`shaded_rows` (lunar-Lambert ``L``; ``psf_sigma_px`` need not be the frame's: the window is 2-5 px deep,
    where the blur hardly changes the shape), aligned on the trace's reference ellipse."""

    cam: object
    sun_dir_camera: tuple
    L: float = 0.0
    psf_sigma_px: float = 1.0

    def rows(self, ell: tuple, angles: np.ndarray, xs: np.ndarray) -> np.ndarray:
        """The model's radiance on each ray (``angles`` about ``ell``'s centre) at ``xs`` px outward from ``ell``,
        blurred by the PSF and the pixel.

        Parameters
        ----------
        ell : tuple
            The trace's reference ellipse ``((r0, c0), (a, b), theta)`` (px, rad); ``a`` is the disc's radius.
        angles : np.ndarray (n,)
            Ray angles ``atan2(d_row, d_col)`` (rad).
        xs : np.ndarray (m,)
            Sample positions (px, outward from the limb).

        Returns
        -------
        np.ndarray (n, m)
            The radiance per ray and sample (:func:`shaded_rows`).
        """
        return shaded_rows(limb_normals(self.cam, ell, angles), self.sun_dir_camera, float(ell[1][0]),
                            pixel_blur(self.psf_sigma_px), self.L, xs)

    def dark_share(self, ell: tuple, angles: np.ndarray, depths: tuple[float, float] = (0.5, 4.0),
                   flat_frac: float = 0.35) -> float:
        """The share of the rays ``angles`` about ``ell`` on which the uniform disc's own shading, unblurred, fails
        the plain flatness test (range over ``depths`` px inside the limb -- about the trace's window, 2-5 px inside
        a foot 1-2 px outside the limb -- above ``flat_frac`` of the mean): how much of a low keep rate the shading
        explains.

        Parameters
        ----------
        ell : tuple
            The reference ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
        angles : np.ndarray (n,)
            Ray angles ``atan2(d_row, d_col)`` (rad).
        depths : tuple of float
            The two depths (px inside the limb) compared.
        flat_frac : float
            The flatness test's largest relative range.

        Returns
        -------
        float
            The share (0-1) of the rays that fail.
        """
        xs = np.array([-depths[1], -depths[0]])
        m = shaded_rows(limb_normals(self.cam, ell, angles), self.sun_dir_camera, float(ell[1][0]), SHADE_FINE,
                         self.L, xs)
        return float(np.mean(np.abs(m[:, 0] - m[:, 1]) > flat_frac * 0.5 * (m[:, 0] + m[:, 1])))


__all__ = ["RayShading", "SHADE_FINE", "limb_normals", "pixel_blur", "shaded_rows"]
