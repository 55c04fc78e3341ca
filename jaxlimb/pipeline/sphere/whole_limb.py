r"""The whole limb of a body whose limb shape is predicted: lit and dark limb, one elliptical sigmoid.

A stage for frames with a strong geometric prior (SPICE: camera, range, body orientation;
:mod:`jaxlimb.geometry.spice`), where the limb's shape in the image is known and its place
is what is measured (the pointing correction).  It measures the **whole** visible limb: the
lit limb (disc brighter than the sky) *and* the dark limb of a night side against a
brighter background -- the case of the Cassini high-phase frames of Enceladus, where the lit
crescent alone is an 80-deg arc on which centre and radius trade off (a circle through the
crescent alone came out 302-305 px against the 288 px the range says).

Steps (the stages of :class:`~jaxlimb.pipeline.sphere.predicted.PredictedLimbSphere`; this module has the fits):

1. the predicted-limb front end (:mod:`jaxlimb.imaging.predicted`): edge points of either
   polarity along the predicted ellipse, fitted with the predicted shape held;
2. the annulus ``|d| <= dr`` around that ellipse (``d`` the distance to it to first order,
   :math:`(\beta - \rho a)/|\nabla\beta|` in the notation of
   :func:`jaxlimb.models.ellipse_coords`), invalid pixels (mask) and clipped pixels
   (saturated: the frame's maximum held by >= 20 pixels) left out;
3. per angular bin the inner and outer levels (medians); a bin is kept when
   :math:`|I - O|` exceeds ``min_snr`` times its noise; intensities are normalised,
   :math:`z_n = (z - O)/(I - O)` (so a dark limb, :math:`I < O`, becomes the same 0-to-1
   step as a lit one) and weighted by :math:`|I - O|/C_{ref}` (the weighted residuals are DN
   residuals over :math:`C_{ref}`, as in :class:`jaxlimb.pipeline.stages.FitData`);
4. the elliptical sigmoid (ESF, Mortari et al. 2016) with the predicted axis ratio and angle
   held, centre, ``a``, ``k`` and the levels free; an outlier pass (Check 3) with a robust
   scale per 10-deg stretch of limb; the annulus is
   re-centred on the fit and the fit repeated;
5. the image of the body centre is the fitted ellipse centre plus the predicted offset
   between the body-centre image and the limb-ellipse centre (sub-pixel near the boresight);
   the on-axis radius and the range scale with :math:`a / a_{pred}`;
   covariance :math:`\hat\sigma^2 (J^\top J)^{-1}` of the fit mapped the same way.

6. a sphere with the Sun direction known, measured on its lit limb only (no dark-limb bins):
   the lit-limb pixels are refitted with the physical lunar-Lambert profile through the
   pipeline's own refit (:func:`jaxlimb.pipeline.profile.fit.fit_lunar_profile`), which removes the
   sigmoid's edge bias (0.35-0.5 px on short arcs);
7. the centre covariance: the larger of the pixel-independent and the cluster-robust one,
   plus an edge-model error (:data:`~jaxlimb.pipeline.sphere.predicted.EDGE_MODEL_SIGMA_PX` through the arc's gains of
   :func:`jaxlimb.imaging.predicted.edge_bias_gain`);
8. lit and dark limb both measured: the model error of their split (the centre fitted on each
   polarity alone, :mod:`jaxlimb.pipeline.sphere.polarity_split`) is added to the centre covariance.

Bodies larger than the frame: the visible arc's circle is found by RANSAC with the radius the range predicts and
the same stages run from there; too-big only when no arc is visible.

Check 4: ``a`` must agree with the predicted one within ``3 u`` (hints
``expected_radius_uncertainty_frac``), else :class:`~jaxlimb.errors.RadiusInconsistentError`.
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import TooManyOutliersError
from ...imaging.predicted import LimbShape
from ...models import ELLIPSE, EllipseParams
from ..checks import MAX_OUTLIER_FRACTION, OUTLIER_SIGMA
from ..options import LocateOptions
from ..sigmoid import K_INIT, levels_held, predict, run_fit
from ..stages import FitData, RefineResult
from .annulus import bin_median


#: Shape parameters held at the prediction.
SHAPE_FIXED = ("theta", "rho")


def ellipse_distance(shape: LimbShape, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Signed distance (px, + outside) to the ellipse to first order, and the eccentric anomaly.

    Parameters
    ----------
    shape : LimbShape
        The limb ellipse (centre, ``a``, ``rho``, ``theta``).
    coords : np.ndarray (n, 2)
        Pixels ``(row, col)``.

    Returns
    -------
    d : np.ndarray (n,)
        :math:`(\beta - \rho a)/|\nabla\beta|` (px, module docstring step 2).
    phi : np.ndarray (n,)
        Eccentric anomaly (rad) in the ellipse's frame.
    """
    x, y = shape.to_frame(coords)
    rho, a = shape.rho, shape.a
    beta = np.hypot(rho * x, y)
    grad = np.hypot(rho * rho * x, y) / np.where(beta > 0, beta, 1.0)
    return (beta - rho * a) / np.where(grad > 0, grad, 1.0), np.arctan2(y, rho * x)


def _annulus(img: np.ndarray, mask: np.ndarray | None, shape: LimbShape, dr: float):
    R, C = img.shape
    ext = shape.a + dr + 2
    cr, cc = shape.center_rc
    r0, r1 = max(0, int(cr - ext)), min(R, int(cr + ext) + 2)
    c0, c1 = max(0, int(cc - ext)), min(C, int(cc + ext) + 2)
    if r1 <= r0 or c1 <= c0:
        raise TooManyOutliersError("the predicted limb annulus lies outside the frame")
    rr, cc_ = np.mgrid[r0:r1, c0:c1]
    coords = np.stack([rr.ravel(), cc_.ravel()], axis=1).astype(np.float64)
    d, phi = ellipse_distance(shape, coords)
    sel = np.abs(d) <= dr
    if mask is not None:
        sel &= mask[r0:r1, c0:c1].ravel()
    z = img[rr.ravel(), cc_.ravel()].astype(np.float64)
    sat = float(np.max(img))
    if np.count_nonzero(img == sat) >= 20:  # clipped pixels carry no edge position (pipeline.locate.saturation_level)
        sel &= z < sat
    return coords[sel], z[sel], d[sel], phi[sel]


def binned_limb_steps(img: np.ndarray, mask: np.ndarray | None, shape: LimbShape, dr: float, noise: float,
                      n_bins: int = 180, min_snr: float = 5.0):  # noqa: ANN201
    """The annulus ``|d| <= dr`` about ``shape`` in ``n_bins`` angular bins and each bin's limb step.

    Parameters
    ----------
    img : np.ndarray (rows, cols)
    mask : np.ndarray of bool or None
        ``True`` = measured pixel.
    shape : LimbShape
        The limb ellipse.
    dr : float
        Annulus half-width (px).
    noise : float
        Image noise (DN).
    n_bins : int
    min_snr : float
        Smallest step, in its noise sigmas, of a significant bin.

    Returns
    -------
    tuple
        ``(coords, z, d, bins, step, significant, sky)``: the annulus pixels ``(n, 2)``, their values, signed
        distance to the limb and bin index ``(n,)``; the bins' inner-minus-outer median level ``(n_bins,)``
        (> 0 where the disc is brighter than the sky), whether it exceeds ``min_snr`` times its noise (two
        medians of >= 3 pixels), and the bins' outer (sky-side) median level.
    """
    coords, z, d, phi = _annulus(img, mask, shape, dr)
    bins = np.minimum(((phi + math.pi) / (2 * math.pi) * n_bins).astype(np.int64), n_bins - 1)
    inner, outer = d <= -0.5 * dr, d >= 0.5 * dr
    lev_in, n_in = bin_median(bins[inner], z[inner], n_bins)
    lev_out, n_out = bin_median(bins[outer], z[outer], n_bins)
    c = lev_in - lev_out
    n_min = np.minimum(n_in, n_out)
    sig = 1.2533 * noise * np.sqrt(2.0 / np.maximum(n_min, 1))  # std of a difference of two medians
    good = (n_min >= 3) & np.isfinite(c) & (np.abs(c) >= min_snr * np.maximum(sig, 1e-12))
    return coords, z, d, bins, c, good, lev_out


def select_whole_limb(img: np.ndarray, mask: np.ndarray | None, shape: LimbShape, dr: float, noise: float,
                      n_bins: int = 180, min_snr: float = 5.0) -> tuple[FitData, dict[str, int]]:
    """Level-normalised annulus data of both polarities (module docstring, steps 2-3).

    Parameters
    ----------
    img, mask, shape, dr, noise, n_bins, min_snr
        As :func:`binned_limb_steps`.

    Returns
    -------
    data : FitData
        Pixels of the significant bins, ``z_n = (z - O)/(I - O)``, weights ``|I - O| / C_ref``.
    counts : dict of str to int
        ``bins_lit``, ``bins_dark`` and ``bins``.

    Raises
    ------
    TooManyOutliersError
        Fewer than 50 pixels in bins with a significant limb step.
    """
    coords, z, _, bins, c, good, lev_out = binned_limb_steps(img, mask, shape, dr, noise, n_bins, min_snr)
    keep = good[bins]
    if np.count_nonzero(keep) < 50:
        raise TooManyOutliersError(f"no significant limb step along the predicted limb ({int(good.sum())} of {n_bins} bins)")
    cb = c[bins[keep]]
    cref = float(np.median(np.abs(cb)))
    zn = (z[keep] - lev_out[bins[keep]]) / cb
    counts = {"bins_lit": int(np.count_nonzero(good & (c > 0))), "bins_dark": int(np.count_nonzero(good & (c < 0))),
              "bins": n_bins}
    return FitData(coords[keep], zn, np.abs(cb) / cref, float(np.nanmedian(lev_out[good])), cref), counts


def _stretches(shape: LimbShape, coords: np.ndarray, cluster_deg: float = 10.0) -> np.ndarray:
    """Index of the ``cluster_deg`` stretch of limb angle of each pixel."""
    _, phi = ellipse_distance(shape, coords)
    m = max(1, int(round(360.0 / cluster_deg)))
    return np.minimum(((phi + math.pi) / (2 * math.pi) * m).astype(np.int64), m - 1)


def _outlier_pass_by_stretch(data: FitData, res, shape: LimbShape, opt: LocateOptions, fixed):
    """Check 3 with a robust scale per 10-deg stretch of limb (the lit and the dark limb differ in
    contrast by 10-100x, so one scale for all would call the lit limb's model error outliers)."""
    r = (data.z - predict(ELLIPSE, res.params, data.coords)) * data.weights
    cl = _stretches(shape, data.coords)
    bad = np.zeros(len(r), bool)
    for c in np.unique(cl):
        i = cl == c
        med = float(np.median(r[i]))
        sig = max(1.4826 * float(np.median(np.abs(r[i] - med))), 1e-12)
        bad[i] = np.abs(r[i] - med) > OUTLIER_SIGMA * sig
    nb = int(np.count_nonzero(bad))
    if nb > MAX_OUTLIER_FRACTION * len(r):
        raise TooManyOutliersError(
            f"Check 3: {nb} of {len(r)} limb pixels ({100.0 * nb / len(r):.1f} %) have residuals above "
            f"{OUTLIER_SIGMA:g} robust sigma of their stretch of limb, above the {MAX_OUTLIER_FRACTION:g} allowed")
    if nb == 0:
        return res, data, 0
    d2 = data.subset(~bad)
    return run_fit(ELLIPSE, d2, res.params, opt, fixed), d2, nb


def fit_pass(img, mask, shape: LimbShape, dr: float, noise: float, opt: LocateOptions):
    """One pass of steps 2-4 (module docstring) about ``shape``: the fit, the limb it puts at the fitted place and
    scale (the shape held) and the bins' counts of each polarity.

    Parameters
    ----------
    img : np.ndarray (rows, cols)
    mask : np.ndarray of bool or None
    shape : LimbShape
        The current limb (predicted, or the last pass's).
    dr : float
        Annulus half-width (px).
    noise : float
        Image noise (DN).
    opt : LocateOptions

    Returns
    -------
    fit : RefineResult
        The ESF with ``theta``, ``rho`` held, after the outlier pass by stretch.
    shape : LimbShape
        ``shape`` moved to the fitted centre and ``a``.
    counts : dict of str to int
        As :func:`select_whole_limb`.
    """
    data, counts = select_whole_limb(img, mask, shape, dr, noise)
    init = EllipseParams(r0=shape.center_rc[0], c0=shape.center_rc[1], a=shape.a, theta=shape.theta, rho=shape.rho,
                         k=K_INIT, ymax=1.0, ymin=0.0)
    fixed = tuple(dict.fromkeys(levels_held(opt) + SHAPE_FIXED))
    res = run_fit(ELLIPSE, data, init, opt, fixed)
    res, data, nb = _outlier_pass_by_stretch(data, res, shape, opt, fixed)
    p = res.params
    new = LimbShape((float(p.r0), float(p.c0)), float(p.a), shape.rho, shape.theta, shape.body_offset_rc)
    return RefineResult(res, data, nb, fixed), new, counts


def cluster_covariance(final: RefineResult, shape: LimbShape, cluster_deg: float = 10.0, h: float = 1e-5,
                       model=ELLIPSE) -> np.ndarray:
    r"""Cluster-robust (sandwich) covariance of the fit, pixels clustered by ``cluster_deg`` of limb angle.

    :math:`\mathrm{cov} = (J^\top W J)^{-1} \big(\sum_c g_c g_c^\top\big) (J^\top W J)^{-1}\,
    \tfrac{m}{m - 1}` with :math:`g_c = \sum_{i \in c} J_i^\top w_i^2 r_i` over the ``m`` clusters
    (Liang & Zeger 1986, *Biometrika* 73:13): errors may be correlated arbitrarily *within* a
    stretch of limb (texture, banding, compression blocks), which the pixel-independent
    :math:`\hat\sigma^2 (J^\top J)^{-1}` ignores.  ``J`` by central differences over ``free``.

    Parameters
    ----------
    final : RefineResult
        The fit and its data.
    shape : LimbShape
        The limb the angles are measured on.
    cluster_deg : float
        Length of a stretch (deg).
    h : float
        Central-difference step of each parameter.
    model : LimbModel
        The fitted model (the ESF, or a limb profile's).

    Returns
    -------
    np.ndarray (p, p)
        Over the fit's free parameters.
    """
    p, free, data = final.fit.params, list(final.fit.free), final.data
    w = np.ones(len(data.z)) if data.weights is None else np.asarray(data.weights)
    r = data.z - predict(model, p, data.coords)
    J = np.empty((len(data.z), len(free)))
    for j, n in enumerate(free):
        v = float(getattr(p, n))
        J[:, j] = (predict(model, p.replace(**{n: v + h}), data.coords)
                   - predict(model, p.replace(**{n: v - h}), data.coords)) / (2 * h)
    Jw = J * w[:, None]
    bread = np.linalg.inv(Jw.T @ Jw)
    cl = _stretches(shape, data.coords, cluster_deg)
    m = int(cl.max()) + 1
    g = np.zeros((m, len(free)))
    np.add.at(g, cl, Jw * (w * r)[:, None])
    used = int(np.count_nonzero(np.bincount(cl, minlength=m)))
    meat = g.T @ g * (used / max(used - 1, 1))
    return bread @ meat @ bread


__all__ = ["SHAPE_FIXED", "binned_limb_steps", "cluster_covariance", "ellipse_distance", "fit_pass", "select_whole_limb"]
