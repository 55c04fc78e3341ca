"""Fits of a traced limb: the known-shape ellipse through the rays (soft-L1), with a glow's lift beside it, the rays'
cluster-robust covariance and coherent-shift floor, and the band's pixels normalised by the rays' levels."""

from __future__ import annotations

import math

import numpy as np

from ...errors import TooManyOutliersError
from ...model_error import cluster_robust_bias_reduced, cluster_robust_covariance
from ...geometry.conic import ellipse_signed_distance
from ...numerics import numerical_jacobian
from ..stages import FitData
from .trace import TracedLimb


def fit_traced(tr: TracedLimb, ell: tuple, free_shape: bool = False) -> tuple:
    """The ellipse through the traced points: ``(r0, c0, a)`` (and ``rho, theta`` when ``free_shape``) by a soft-L1
    geometric fit (scale 0.5 px), started at ``ell``.  With ``tr.glow_term`` (known shape only) the points'
    residuals include the glow's lift ``c / A_ray`` (:func:`glow_lift_column`, :func:`fit_traced_glow`).

    Parameters
    ----------
    tr : TracedLimb
        The trace; its kept rays' limb points are fitted.
    ell : tuple
        The start ``((r0, c0), (a, b), theta)`` (px, rad); its ``b / a`` and ``theta`` are held unless ``free_shape``.
    free_shape : bool
        Fit ``rho, theta`` too.

    Returns
    -------
    tuple
        The fitted ellipse ``((r0, c0), (a, b), theta)`` (px, rad).

    Raises
    ------
    TooManyOutliersError
        Fewer than 20 kept rays.
    """
    from scipy.optimize import least_squares

    pts = tr.points[tr.ok]
    if pts.shape[0] < 20:
        raise TooManyOutliersError(f"the limb trace kept {pts.shape[0]} rays with a limb against the sky (need >= 20)")
    if tr.glow_term and not free_shape:
        return fit_traced_glow(tr, ell)[0]
    (r0, c0), (a, b), th = ell

    def shape(x):
        rho, t = (x[3], x[4]) if free_shape else (b / a, th)
        return ((x[0], x[1]), (x[2], x[2] * rho), t)

    x0 = [r0, c0, a] + ([b / a, th] if free_shape else [])
    res = least_squares(lambda x: ellipse_signed_distance(pts, shape(x)), x0, loss="soft_l1", f_scale=0.5, x_scale="jac")
    (r, c), (aa, bb), t = shape(res.x)
    return ((float(r), float(c)), (float(aa), float(bb)), float(t))


GLOW_LIFT_Z = 4.0
"""The z-score (cluster-robust, :func:`fit_traced_glow`) above which a patchy limb's traced points are fitted with
the glow's lift.  Cloud edges alone lift some rays and not others, at random along the arc; a glow lifts the dim
rays systematically.  A threshold tuned on the project's cloudy Earths with and without a glow
(``docs/validation/constants.md#glow_lift_z``)."""


def glow_lift_column(tr: TracedLimb) -> np.ndarray:
    """Per kept ray, ``1 / (P - sky)`` over its median: the shape of the outward lift of a ray's half-level crossing
    by a glow above the limb.  A glow adds radiance ``g(x)`` of its own (the same in DN along the limb: it does not
    depend on the surface's albedo) to a step of height ``A = P - sky``; the crossing of ``sky + A/2`` moves out by
    ``g / |I'| ~ sqrt(2 pi) sigma g / A`` (first order), so a ray over ocean (``A`` ten times smaller than over a
    cloud) is lifted ten times more.  Along a cloudy limb ``1/A`` varies by an order of magnitude, so the lift is
    not the radius's constant and is estimated beside the ellipse (on a uniform limb it would be).

    Parameters
    ----------
    tr : TracedLimb
        The trace.

    Returns
    -------
    np.ndarray (n_kept,)
        The column (1 at the median ray).
    """
    inv = 1.0 / np.maximum(tr.inside[tr.ok] - tr.sky, 1e-12)
    return inv / float(np.median(inv))


def glow_lift_columns(tr: TracedLimb, tilt: bool = True) -> np.ndarray:
    """:func:`glow_lift_column`, and with ``tilt`` (and ``tr.glow_tilt``, ``tr.lit_angle`` known) the same times
    ``cos psi``, ``psi`` the ray's angle from the lit side's direction: a glow lit by the Sun is brighter toward it,
    ``g (1 + t cos psi)`` (the profile's ``glow_tilt``, :mod:`jaxlimb.models.lunar_lambert`), and lifts the sunward
    rays more, which moves the ellipse toward the Sun.  The tilt is nearly a centre shift along the Sun (the two
    differ only by ``1 / A_ray``), so it is not fitted (:func:`fit_traced_glow`): it is marginalised in the
    covariance (:func:`trace_model_cov`).  The pipeline asks for the tilt near zero phase only
    (:data:`jaxlimb.pipeline.ellipsoid.patchy.GLOW_TILT_MAX_PHASE_DEG`), where the glow changes fast with the
    solar zenith angle along the limb.

    Parameters
    ----------
    tr : TracedLimb
        The trace.
    tilt : bool
        Add the tilt's column when the trace asks for it.

    Returns
    -------
    np.ndarray (n_kept, k)
        ``k = 1`` (the lift) or 2 (lift and tilt).
    """
    col = glow_lift_column(tr)
    if not (tilt and tr.glow_tilt) or tr.lit_angle is None:
        return col[:, None]
    return np.column_stack([col, col * np.cos(tr.angles[tr.ok] - tr.lit_angle)])


def _glow_residuals(tr: TracedLimb, ell: tuple, tilt: bool):
    pts, cols = tr.points[tr.ok], glow_lift_columns(tr, tilt)
    (_, _), (a, b), th = ell

    def res(x):
        return ellipse_signed_distance(pts, ((x[0], x[1]), (x[2], x[2] * b / a), th)) - cols @ x[3:]

    return res


def fit_traced_glow(tr: TracedLimb, ell: tuple) -> tuple[tuple, float, float]:
    """The known-shape ellipse through the traced points with the glow's lift ``c / A_ray`` (:func:`glow_lift_column`)
    fitted beside ``(r0, c0, a)`` (soft-L1, as :func:`fit_traced`).

    Parameters
    ----------
    tr : TracedLimb
        The trace.
    ell : tuple
        The start ``((r0, c0), (a, b), theta)`` (px, rad); ``b / a`` and ``theta`` held.

    Returns
    -------
    ell : tuple
        The fitted ellipse ``((r0, c0), (a, b), theta)``.
    c : float
        The lift (px at the median ray).
    z : float
        Its z-score with the cluster-robust sigma of :func:`trace_model_cov` (10 deg clusters, CR2).

    Raises
    ------
    TooManyOutliersError
        Fewer than 20 kept rays.
    """
    from scipy.optimize import least_squares

    if int(tr.ok.sum()) < 20:
        n = int(tr.ok.sum())
        raise TooManyOutliersError(f"the limb trace kept {n} rays with a limb against the sky (need >= 20)")
    (r0, c0), (a, b), th = ell
    res = _glow_residuals(tr, ell, tilt=False)
    x = least_squares(res, [r0, c0, a, 0.0], loss="soft_l1", f_scale=0.5, x_scale="jac").x
    C = _cluster_cov(tr, res, x, 10.0, True)
    z = float(x[3] / math.sqrt(C[3, 3])) if C[3, 3] > 0 else 0.0
    return ((float(x[0]), float(x[1])), (float(x[2]), float(x[2] * b / a)), th), float(x[3]), z


def _cluster_cov(tr: TracedLimb, res, x0: np.ndarray, bin_deg: float, bias_reduced: bool) -> np.ndarray:
    """Cluster-robust covariance of the parameters ``x0`` of the residuals ``res`` of the kept rays (clusters of
    ``bin_deg`` of ray angle); central-difference Jacobian."""
    t = tr.angles[tr.ok]
    r = res(x0)
    J = numerical_jacobian(res, x0, 1e-3)
    groups = np.floor((t - t.min()) / math.radians(bin_deg)).astype(int)
    return (cluster_robust_bias_reduced if bias_reduced else cluster_robust_covariance)(J, r, groups)


def trace_model_cov(tr: TracedLimb, ell: tuple, bin_deg: float = 10.0, bias_reduced: bool = True) -> np.ndarray:
    """Model error of an albedo-patchy limb: the cluster-robust (sandwich) covariance of ``(r0, c0, a)`` of the
    geometric fit of the traced points about ``ell``, clusters of ``bin_deg`` of ray angle.  Albedo structure
    across the limb (a cloud edge 0-2 px inside it) shifts the edge of whole stretches of rays alike; the
    pixel noise of the band fit does not see that, the spread of those stretches does.  With ``tr.glow_term`` the
    glow's lift (and tilt) is fitted beside the ellipse and marginalised.

    The bias-reduced sandwich (CR2, :func:`~jaxlimb.model_error.cluster_robust_bias_reduced`) by default: with few
    rays in few sectors the plain sandwich underestimates the centre's sigma, and with many well-spread sectors the
    two agree.

    Parameters
    ----------
    tr : TracedLimb
        The trace.
    ell : tuple
        The fitted ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    bin_deg : float
        Width (deg) of the clusters of ray angle.
    bias_reduced : bool
        CR2; ``False``: the plain sandwich (CR1), the gate of
        :func:`~jaxlimb.pipeline.ellipsoid.patchy.patchy_geometry`.

    Returns
    -------
    np.ndarray (3, 3)
        Covariance of ``(r0, c0, a)`` (px^2).
    """
    (r0, c0), (a, b), th = ell
    if tr.glow_term:  # the lift (and its tilt) beside the ellipse: their uncertainty is the ellipse's too (marginal)
        res = _glow_residuals(tr, ell, tilt=True)
        from scipy.optimize import least_squares

        k = glow_lift_columns(tr).shape[1]
        c = least_squares(lambda y: res(np.concatenate([[r0, c0, a], y])), [0.0] * k, loss="soft_l1", f_scale=0.5).x
        return _cluster_cov(tr, res, np.concatenate([[r0, c0, a], c]), bin_deg, bias_reduced)[:3, :3]
    pts = tr.points[tr.ok]

    def d(x):
        return ellipse_signed_distance(pts, ((x[0], x[1]), (x[2], x[2] * b / a), th))

    return _cluster_cov(tr, d, np.array([r0, c0, a], float), bin_deg, bias_reduced)


def coherent_shift_var(tr: TracedLimb, ell: tuple, bin_deg: float = 10.0, min_rays: int = 3) -> float:
    """Variance (px^2, per axis) of the centre shift an albedo-patchy limb's bias field hides in the fit.

    Clouds within a pixel of the limb move whole stretches of traced rays alike.  The known-shape fit absorbs the
    part of that field that looks like a radius (``k = 0``) or a centre shift (``k = 1``), so neither the residuals
    nor their cluster sandwich (:func:`trace_model_cov`) can see it; they see the rest.  With no preferred harmonic
    in an albedo field, the absorbed shift has the visible part's power: the sector means of the rays' distances
    from ``ell`` less their fit by ``1, cos psi, sin psi`` (and the glow's lift, :func:`glow_lift_column`, when
    ``tr.glow_term``) have mean square ``m^2`` of which the rays' own scatter contributes ``var(d) / n_sector``, and
    ``m^2 - var(d)/n`` per axis is the hidden shift's variance.  Used as a floor on the centre's variance
    (:func:`~jaxlimb.pipeline.ellipsoid.profile.floor_center_var`).

    Parameters
    ----------
    tr : TracedLimb
        The trace.
    ell : tuple
        The fitted ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    bin_deg : float
        Width (deg) of the sectors of ray angle.
    min_rays : int
        Fewest rays of a sector used.

    Returns
    -------
    float
        The variance (px^2, at least 0; 0 with fewer than 20 rays or 2 sectors).
    """
    ok = tr.ok
    if int(ok.sum()) < 20:
        return 0.0
    psi = tr.angles[ok]
    d = ellipse_signed_distance(tr.points[ok], ell)
    cols = [np.ones_like(psi), np.cos(psi), np.sin(psi)] + ([glow_lift_column(tr)] if tr.glow_term else [])
    A = np.column_stack(cols)  # what the fit absorbs (radius, centre, a glow's lift): the visible field is the rest
    d = d - A @ np.linalg.lstsq(A, d, rcond=None)[0]
    g = np.floor((psi - psi.min()) / math.radians(bin_deg)).astype(int)
    counts = np.bincount(g)
    sums = np.bincount(g, weights=d)
    use = counts >= min_rays
    if use.sum() < 2:
        return 0.0
    means = sums[use] / counts[use]
    return max(float(np.mean(means**2) - np.mean(np.var(d) / counts[use])), 0.0)


def normalised_band(img: np.ndarray, pts: np.ndarray, tr: TracedLimb) -> tuple[np.ndarray, FitData]:
    """The band's pixels with their ray's levels (module docstring of :mod:`jaxlimb.pipeline.ellipsoid.trace`):
    ``z_n = (z - s) / (P_ray - s)`` with weights ``(P_ray - s) / C_ref``, each pixel taking the nearest ray in angle;
    pixels of rejected rays are left out.

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image.
    pts : np.ndarray (n, 2)
        The band's pixels ``(row, col)``.
    tr : TracedLimb
        The trace whose per-ray levels normalise them.

    Returns
    -------
    keep : np.ndarray (n,) of bool
        The pixels kept.
    data : FitData
        The kept pixels' normalised values and weights, ``offset = s`` (the sky, DN), ``scale = C_ref`` (the
        median contrast, DN).
    """
    z = np.asarray(img[pts[:, 0].astype(int), pts[:, 1].astype(int)], float)
    ang = np.arctan2(pts[:, 0] - tr.center_rc[0], pts[:, 1] - tr.center_rc[1])
    order = np.argsort(np.mod(tr.angles, 2 * np.pi))
    a_sorted = np.mod(tr.angles, 2 * np.pi)[order]
    idx = np.clip(np.searchsorted(a_sorted, np.mod(ang, 2 * np.pi)), 0, a_sorted.size - 1)
    prev = np.clip(idx - 1, 0, a_sorted.size - 1)
    near = np.where(np.abs(a_sorted[prev] - np.mod(ang, 2 * np.pi)) < np.abs(a_sorted[idx] - np.mod(ang, 2 * np.pi)),
                    prev, idx)
    P = tr.inside[order][near]
    keep = np.isfinite(P)
    c = P[keep] - tr.sky
    cref = float(np.median(c)) if c.size else 1.0
    return keep, FitData(pts[keep], (z[keep] - tr.sky) / c, c / cref, tr.sky, cref)


__all__ = ["GLOW_LIFT_Z", "coherent_shift_var", "fit_traced", "fit_traced_glow", "glow_lift_column", "glow_lift_columns", "normalised_band", "trace_model_cov"]
