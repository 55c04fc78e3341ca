r"""The few-pixel body as a blob: where it is (the candidates stage of :class:`~jaxlimb.pipeline.small.body.SmallBody`)
and its centre of brightness corrected for the phase (the fallback when the disc fit fails).

Candidates.  The image smoothed by a Gaussian of ``max(1, a/2)`` px (about the matched filter of a disc of radius
``a`` blurred by a ~1 px PSF); its highest point (within :data:`SEARCH_PX` of the hints' ``expected_center_rc`` when
given, invalid pixels left out); the sky and the noise from the ring :data:`SKY_RING_PX` around it (median, MAD).
Check "no body": the brightest raw pixel near the peak less than :data:`MIN_PEAK_SNR` noise sigmas above the sky.
Check "size": the blob much larger than the hints' expected radius (:data:`MAX_SIZE_RATIO`): a resolved body.

Centre of brightness (GIANT's moment algorithm, ``giant.relative_opnav.estimators.moment_algorithm``): the first
moment of ``z - sky`` over the pixels of the connected region above ``sky + 3 noise`` about the peak, dilated by
:data:`MOMENT_DILATE_PX` (the PSF's wings), and the phase correction: the offset of the lunar-Lambert disc's own
centre of brightness from its centre at the phase and radius of the hints
(:func:`~jaxlimb.models.small_disc.photocentre_offset`; GIANT's "rastered" correction, here of the same disc the fit
uses).  Covariance: the first moment's noise, :math:`\sum_i (x_i - \bar x)^2 \sigma^2 / F^2`, plus the correction's
own uncertainty -- the radius's (the hints' fraction) and the law's (:data:`LAW_SIGMA` of ``L``), both as the change
of the correction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import NoBodyError, RadiusInconsistentError

#: Radius (px) of the search about the hints' ``expected_center_rc``.
SEARCH_PX = 30.0
#: Inner and outer radius (px, beyond the expected disc) of the ring that gives the sky and the noise.
SKY_RING_PX = (8.0, 20.0)
#: Check "no body": the brightest pixel near the peak must be this many noise sigmas above the sky.
MIN_PEAK_SNR = 5.0
#: Dilation (px) of the region above ``sky + 3 noise`` over which the first moment is taken.
MOMENT_DILATE_PX = 2
#: Check "size": the region above ``sky + 3 noise`` about the peak, as the radius of a disc of its area, at most this
#: times the expected radius plus :data:`MAX_SIZE_PAD_PX` (the PSF's and the noise's widening).
MAX_SIZE_RATIO = 2.0
MAX_SIZE_PAD_PX = 4.0
#: 1-sigma of the lunar-Lambert weight ``L`` (the law between Lambert, 0, and Lommel-Seeliger, 1) in the covariance
#: of the phase correction: a quarter of its range.
LAW_SIGMA = 0.25


@dataclass(frozen=True)
class BlobCandidates:
    """The blob: smoothed peak, centre of brightness, sky, noise, the raw peak's SNR, the expected radius (px) and its
    fractional uncertainty (``None``: no size from the hints)."""

    peak_rc: tuple[int, int]
    centroid_rc: tuple[float, float]
    centroid_cov: np.ndarray
    sky: float
    noise: float
    flux: float
    snr: float
    second_moment: float
    expected_radius_px: float | None
    radius_uncertainty: float
    front_end: str = "blob"
    info: dict[str, Any] = field(default_factory=dict)


def _peak(img: np.ndarray, valid: np.ndarray | None, a: float, near_rc) -> tuple[int, int]:
    """The highest point of the smoothed image (near ``near_rc`` when given)."""
    from scipy import ndimage

    sm = ndimage.gaussian_filter(img, max(1.0, 0.5 * a), mode="nearest")
    if valid is not None:
        sm = np.where(valid, sm, -np.inf)
    if near_rc is not None:
        rr, cc = np.ogrid[: img.shape[0], : img.shape[1]]
        far = np.hypot(rr - float(near_rc[0]), cc - float(near_rc[1])) > SEARCH_PX + a
        if not far.all():
            sm = np.where(far, -np.inf, sm)
    k = int(np.argmax(sm))
    return (k // img.shape[1], k % img.shape[1])


def _ring(img: np.ndarray, valid: np.ndarray | None, peak, a: float) -> tuple[float, float]:
    """Sky (median) and noise (1.4826 MAD) in the ring :data:`SKY_RING_PX` beyond the disc about ``peak``."""
    r_in, r_out = a + SKY_RING_PX[0], a + SKY_RING_PX[1]
    r0, r1 = max(0, int(peak[0] - r_out)), min(img.shape[0], int(peak[0] + r_out) + 1)
    c0, c1 = max(0, int(peak[1] - r_out)), min(img.shape[1], int(peak[1] + r_out) + 1)
    rr, cc = np.mgrid[r0:r1, c0:c1]
    d = np.hypot(rr - peak[0], cc - peak[1])
    m = (d >= r_in) & (d <= r_out)
    if valid is not None:
        m &= valid[r0:r1, c0:c1]
    z = img[r0:r1, c0:c1][m]
    if z.size < 20:  # a body near the corner of a small frame: the whole frame's border
        z = np.concatenate([img[0], img[-1], img[:, 0], img[:, -1]])
    sky = float(np.median(z))
    return sky, max(1.4826 * float(np.median(np.abs(z - sky))), 1e-9)


def centre_of_brightness(img: np.ndarray, valid: np.ndarray | None, peak, sky: float, noise: float):
    """First moment of ``z - sky`` over the blob about ``peak`` (module docstring): ``(centre, covariance 2x2, flux,
    second moment per axis, pixels above sky + 3 noise)``.

    Parameters
    ----------
    img : numpy.ndarray
        The image ``(rows, cols)`` (DN).
    valid : numpy.ndarray of bool or None
        Valid pixels (``None``: all).
    peak : tuple of int
        ``(row, col)`` of the smoothed peak; the blob is the region connected to it.
    sky, noise : float
        Sky level and noise sigma (DN).

    Returns
    -------
    centre : tuple of float
        ``(row, col)`` (px) of the centre of brightness.
    cov : numpy.ndarray
        Its ``2 x 2`` covariance (px^2) from the noise.
    flux : float
        Sum of ``z - sky`` over the blob (DN).
    second_moment : float
        Mean second moment per axis (px^2).
    area : int
        Number of pixels above ``sky + 3 noise`` in the region, before the dilation.

    Raises
    ------
    NoBodyError
        The blob holds no flux above the sky.
    """
    from scipy import ndimage

    above = img > sky + 3.0 * noise
    if valid is not None:
        above &= valid
    lab, _ = ndimage.label(above)
    region = lab == lab[peak] if lab[peak] else np.zeros_like(above)
    region[peak] = True
    area = int(np.count_nonzero(region))
    region = ndimage.binary_dilation(region, iterations=MOMENT_DILATE_PX)
    if valid is not None:
        region &= valid
    rr, cc = np.nonzero(region)
    w = img[rr, cc] - sky
    F = float(w.sum())
    if not F > 0:
        raise NoBodyError("no body: the blob at the brightest point holds no flux above the sky")
    r_bar, c_bar = float((w * rr).sum() / F), float((w * cc).sum() / F)
    dr, dc = rr - r_bar, cc - c_bar
    cov = noise * noise / (F * F) * np.array([[np.sum(dr * dr), np.sum(dr * dc)], [np.sum(dr * dc), np.sum(dc * dc)]])
    m2 = float(0.5 * (w * (dr * dr + dc * dc)).sum() / F)
    return (r_bar, c_bar), cov, F, m2, area


def find_blob(img: np.ndarray, valid: np.ndarray | None, expected_radius_px: float | None, radius_uncertainty: float,
              near_rc=None) -> BlobCandidates:
    """Stage "candidates" of the small body (module docstring).

    Parameters
    ----------
    img : numpy.ndarray
        The image ``(rows, cols)`` (DN).
    valid : numpy.ndarray of bool or None
        Valid pixels (``None``: all).
    expected_radius_px : float or None
        Apparent radius (px) from the hints (``None``: unknown, 3 px assumed for the search and the ring).
    radius_uncertainty : float
        Fractional 1-sigma of ``expected_radius_px``.
    near_rc : tuple of float, optional
        ``(row, col)`` (px) the search is restricted to within :data:`SEARCH_PX`.

    Returns
    -------
    BlobCandidates

    Raises
    ------
    NoBodyError
        The brightest point is fewer than :data:`MIN_PEAK_SNR` noise sigmas above the sky.
    RadiusInconsistentError
        The blob is much larger than the expected radius (check "size").
    """
    a = float(expected_radius_px) if expected_radius_px is not None else 3.0
    peak = _peak(img, valid, a, near_rc)
    sky, noise = _ring(img, valid, peak, a)
    r0, r1 = max(0, peak[0] - 2), min(img.shape[0], peak[0] + 3)
    c0, c1 = max(0, peak[1] - 2), min(img.shape[1], peak[1] + 3)
    top = float(np.max(img[r0:r1, c0:c1]))
    snr = (top - sky) / noise
    if not snr >= MIN_PEAK_SNR:
        raise NoBodyError(f"no body: the brightest point is {snr:.3g} noise sigmas above the sky, fewer than "
                          f"{MIN_PEAK_SNR:g}")
    cen, cov, F, m2, area = centre_of_brightness(img, valid, peak, sky, noise)
    r_eq = math.sqrt(area / math.pi)
    if expected_radius_px is not None and r_eq > MAX_SIZE_RATIO * a + MAX_SIZE_PAD_PX:
        raise RadiusInconsistentError(f"the blob at the brightest point is {r_eq:.3g} px in radius above the sky, more "
                                      f"than {MAX_SIZE_RATIO:g} x the {a:.3g} px the hints expect + {MAX_SIZE_PAD_PX:g} px "
                                      "of blur: not a few-pixel body")
    return BlobCandidates(peak, cen, cov, sky, noise, F, float(snr), m2, expected_radius_px, radius_uncertainty)


def phase_corrected(cand: BlobCandidates, offset_rc, d_offset_da, d_offset_dl) -> tuple[tuple[float, float], np.ndarray]:
    """The centre of brightness less the phase offset, and its covariance (module docstring): ``d_offset_da`` and
    ``d_offset_dl`` the offset's change per px of radius and per unit of ``L``.

    Parameters
    ----------
    cand : BlobCandidates
        The blob, with its centre of brightness and covariance.
    offset_rc : array_like
        Phase offset ``(d_row, d_col)`` (px) of the disc's centre of brightness from its centre.
    d_offset_da : array_like
        Change of the offset ``(2,)`` per px of radius.
    d_offset_dl : array_like
        Change of the offset ``(2,)`` per unit of ``L``.

    Returns
    -------
    centre : tuple of float
        ``(row, col)`` (px) of the body centre.
    cov : numpy.ndarray
        Its ``2 x 2`` covariance (px^2).
    """
    c = (cand.centroid_rc[0] - float(offset_rc[0]), cand.centroid_rc[1] - float(offset_rc[1]))
    a = cand.expected_radius_px or 0.0
    ga = np.asarray(d_offset_da, float) * cand.radius_uncertainty * a
    gl = np.asarray(d_offset_dl, float) * LAW_SIGMA
    return c, cand.centroid_cov + np.outer(ga, ga) + np.outer(gl, gl)


__all__ = ["BlobCandidates", "LAW_SIGMA", "MIN_PEAK_SNR", "centre_of_brightness", "find_blob", "phase_corrected"]
