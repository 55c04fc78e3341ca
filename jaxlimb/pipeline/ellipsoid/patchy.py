"""An albedo-patchy limb (clouds) measured from its traced rays as well as from the band fit: the known-shape
ellipse through the rays (with a glow's lift and the shading's bias), the band fit kept unless it left the rays'
95 % region, and the other estimate and the traced step's asymmetry kept as witnesses (model error)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ...errors import TooManyOutliersError
from ..stages import EllipsoidEdge, Frame
from .band import shifted, with_ellipse
from .model import EllipsoidModel, position
from .start import ray_shading
from .trace import shading_corrected, shading_offsets, shading_sigma, trace_limb
from .trace_fit import GLOW_LIFT_Z, fit_traced, fit_traced_glow, trace_model_cov


def ray_geometry(body: EllipsoidModel, frame: Frame, edge: EllipsoidEdge, passes: int = 2) -> EllipsoidEdge:
    """An albedo-patchy limb's geometry from its rays, not from the band fit (attitude known): the known-shape
    ellipse through the traced limb points (:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.fit_traced`, soft-L1), the
    rays re-sampled about it and the shape re-predicted at its position, ``passes`` times, starting from the traced
    start ellipse.  Why: the band fit of the level-normalised pixels is pulled by the cloud edges a few px inside
    the limb that survive the per-ray flatness test, while the ray fit weighs each ray's limb point once.  The edge
    fit's other parameters (levels, kernel) are kept; its ``(r0, c0, a)`` covariance is replaced by the rays'
    cluster-robust one in the refit stage (:func:`~jaxlimb.pipeline.ellipsoid.profile.fit_profile_ellipsoid`).

    Parameters
    ----------
    body : EllipsoidModel
        The body (attitude known: ``rho, theta`` predicted).
    frame : Frame
        The prepared frame (image, camera, Sun direction for the shading correction).
    edge : EllipsoidEdge
        The band fit, whose ``pixels.trace`` is the traced start.
    passes : int
        Number of trace-and-fit passes.

    Returns
    -------
    EllipsoidEdge
        The edge answering the rays' ellipse and position, with ``pixels.trace`` the last trace
        (``ray_fit=True``) and ``shading_shift`` the move ``(d_r0, d_c0, d_a)`` (px) of the shading
        correction (``None`` when none was made).

    Raises
    ------
    TooManyOutliersError
        Too few rays with a limb against the sky.
    """

    pix, cam = edge.pixels, frame.cam
    search = max(6.0, 2.0 * body.eo.band_px)
    ell, p, tr, fitted = pix.ellipse, edge.p, pix.trace, pix.ellipse
    for _ in range(passes):
        rho, th = body.predicted_shape(cam, -p)
        ell = (ell[0], (ell[1][0], ell[1][0] * rho), th)
        tr, fitted, shift = _rays_once(body, frame, trace_limb(frame.img, ell, pix.lit_dir, pix.half, search,
                                                                shade=tr.shade), ell)
        p, _ = position(body, cam, fitted, p)
        ell = fitted
    return replace(with_ellipse(edge, fitted), pixels=replace(pix, trace=tr, ray_fit=True), p=p, shading_shift=shift)


def _rays_once(body: EllipsoidModel, frame: Frame, tr: Any, ell: tuple) -> tuple[Any, tuple, tuple | None]:
    """One pass of :func:`ray_geometry` on trace ``tr`` about ``ell``: the rays' ellipse (:func:`_fit_rays`) with the
    crossings' shading bias removed (:func:`_shaded`), and the shift ``(dr0, dc0, da)`` that removal made (``None``
    when it was not made).  The glow's lift and the shading model do not compose (each moves the crossings by an
    amount set by the ray's brightness, and the two together move the centre), so a glow fitted on the raw crossings is kept alone -- except on a shading-flattened
    trace (a dark Lambert limb, :class:`~jaxlimb.pipeline.ellipsoid.shading.RayShading`), whose raw crossings lie
    inside the limb, deepest where the limb is darkest: a ``c / A_ray`` lift takes that for a glow.  There only the
    shading is removed: a glow above a dark limb is not modelled (such a trace arises only near zero phase,
    :func:`wide_trace`; ``docs/validation/constants.md#glow-and-shading``)."""

    def moved(a: tuple, b: tuple) -> tuple:
        return (a[0][0] - b[0][0], a[0][1] - b[0][1], a[1][0] - b[1][0])

    if tr.shade is not None:
        plain, shaded = fit_traced(tr, ell), _shaded(body, frame, tr, ell)
        fitted = fit_traced(shaded, ell)
        return shaded, fitted, moved(fitted, plain)
    tr, fitted = _fit_rays(tr, ell, glow_tilt=_glow_tilt(frame, ell[0]))
    shaded = tr if tr.glow_term else _shaded(body, frame, tr, ell)
    if shaded is tr:
        return tr, fitted, None
    corrected = fit_traced(shaded, ell)
    return shaded, corrected, moved(corrected, fitted)


def _shaded(body: EllipsoidModel, frame: Frame, tr: Any, ell: tuple) -> Any:
    """The traced rays with their crossings' shading bias removed (:data:`~jaxlimb.pipeline.ellipsoid.start.PATCHY_SHADING_L`; needs the
    Sun direction); ``tr`` unchanged without it or with fewer than 20 rays."""

    sh = ray_shading(body, frame)
    if sh is None or tr.ok.sum() < 20:
        return tr
    sig = shading_sigma(frame.img, tr, ell, frame.cam, sh.sun_dir_camera, sh.L)
    return shading_corrected(tr, shading_offsets(tr, ell, frame.cam, sh.sun_dir_camera, sig, sh.L))


GLOW_TILT_MAX_PHASE_DEG = 20.0
"""At or below this phase (deg) a glow fitted above a patchy limb (:func:`_fit_rays`) carries its tilt toward the Sun
in the covariance (:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.glow_lift_columns`).  A glow is sunlight scattered by
the atmosphere at the limb's tangent points, whose solar zenith angle is ``acos(sin(phase) cos(psi))``: at 20 deg of
phase or less it is 70 deg or more all along the lit limb, where the twilight glow changes fast with it (the full
disc from L1).  On a gibbous limb most tangent points are in full sunlight and the glow is nearly uniform: there
the tilt's marginal only widens the sigmas (``docs/validation/constants.md#glow_tilt_max_phase_deg``)."""


def _glow_tilt(frame: Frame, center_rc) -> bool:
    """Whether the phase at the body's image ``center_rc`` (Sun known) is at most :data:`GLOW_TILT_MAX_PHASE_DEG`."""
    return frame.sun_known and math.degrees(frame.phase(center_rc)) <= GLOW_TILT_MAX_PHASE_DEG


def _fit_rays(tr: Any, ell: tuple, glow_tilt: bool = False) -> tuple[Any, tuple]:
    """The known-shape ellipse through the traced rays (:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.fit_traced`), with the
    glow's lift ``c / A_ray`` fitted beside it when it is positive at more than
    :data:`~jaxlimb.pipeline.ellipsoid.trace_fit.GLOW_LIFT_Z` cluster-robust sigmas
    (:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.fit_traced_glow`; the returned trace then has ``glow_term`` set, so its
    covariance carries the lift too, and :func:`patchy_geometry` answers with the rays: the band fit has no glow).

    Why: a glow above a cloudy limb adds the same radiance over ocean and cloud, so it lifts the half-level crossings
    of the dim ocean rays ten times more than the cloud rays' (the lift is ``c / (P_ray - s)``): the traced limb is an
    ellipse pushed out where the limb is dim, and the part of that push which varies along the arc moves the centre.
    At 380 000 km the inside level ``P``, 2-5 px deep, is surface 10-16 deg from the limb, a poorer proxy of the
    limb's own radiance, and the lift a poorer model (``docs/validation/constants.md#glow_lift_z``)."""
    from dataclasses import replace as _replace

    e, c, z = fit_traced_glow(tr, ell)
    if c > 0.0 and z > GLOW_LIFT_Z:  # near zero phase its tilt too, in the covariance (GLOW_TILT_MAX_PHASE_DEG)
        return _replace(tr, glow_term=True, glow_tilt=glow_tilt), e
    return tr, fit_traced(tr, ell)


def patchy_geometry(body: EllipsoidModel, frame: Frame, edge: EllipsoidEdge, chi2: float = 5.99) -> EllipsoidEdge:
    """An albedo-patchy limb (attitude known) measured twice: the band fit of the level-normalised pixels (``edge``)
    and the known-shape ellipse through the traced rays (:func:`ray_geometry`).  The band fit is kept unless its
    centre lies outside the rays' 95 % region (``d^T C_rays^-1 d > chi2`` on ``(r0, c0)``, ``C_rays`` the rays'
    cluster-robust covariance, :func:`~jaxlimb.pipeline.ellipsoid.trace_fit.trace_model_cov`), when the band fit
    followed cloud edges, or the rays fitted a glow's lift; the rays' ellipse answers then, and when the band fit did
    not converge (no witness then).  Either way the other estimate's ``(r0, c0, a)`` is kept as ``witness``: two
    models of the same limb, their difference is model error (added to the covariance by
    :func:`~jaxlimb.pipeline.ellipsoid.profile.fit_profile_ellipsoid`, as a rejected profile's is).

    Parameters
    ----------
    body : EllipsoidModel
        The body (attitude known).
    frame : Frame
        The prepared frame.
    edge : EllipsoidEdge
        The band fit (``band_converged`` says whether it converged).
    chi2 : float
        The chi-square bound with 2 degrees of freedom (5.99: 95 %).

    Returns
    -------
    EllipsoidEdge
        The band fit (shifted by the rays' shading correction) or the rays' fit, with ``witness`` (px) and the
        traced step's ``asymmetry`` ``(d_r0, d_c0, 0)`` (px, ``None`` when it could not be measured).

    Raises
    ------
    TooManyOutliersError
        Too few rays and no converged band fit.
    """

    try:
        rays = ray_geometry(body, frame, edge)
    except TooManyOutliersError:  # fewer than 20 rays with a limb against the sky: the band fit alone, if any
        if edge.band_converged:
            return edge
        raise
    asym = _asymmetry(frame.img, rays.fitted, rays.pixels.lit_dir, rays.pixels.half, rays.pixels.trace.shade)
    if not edge.band_converged:
        return replace(rays, asymmetry=asym)

    def geo(e: EllipsoidEdge) -> np.ndarray:
        return np.array([e.fitted[0][0], e.fitted[0][1], e.fitted[1][0]])

    d = geo(edge) - geo(rays)
    C = trace_model_cov(rays.pixels.trace, rays.fitted, bias_reduced=False)[:2, :2]
    try:
        m2 = float(d[:2] @ np.linalg.solve(C, d[:2]))
    except np.linalg.LinAlgError:
        m2 = math.inf
    if m2 > chi2 or rays.pixels.trace.glow_term:  # (the band fit has no glow: the rays' lift answers)
        return replace(rays, witness=tuple(float(v) for v in geo(edge)), asymmetry=asym)
    return replace(shifted(edge, rays.shading_shift), witness=tuple(float(v) for v in geo(rays)), asymmetry=asym)


def _asymmetry(img: np.ndarray, ell: tuple, lit_dir, half: float,
               shade: Any = None) -> tuple[float, float, float] | None:
    """The traced step's asymmetry as a witness of the patchy limb's centre: the known-shape ellipse ``ell`` (start)
    through the rays' 30 % crossings less the one through their 70 % crossings, ``(dr0, dc0, 0)``.  A symmetric
    blurred step moves only the radius between the two (by ~1 PSF sigma; left out, it is the step's width, not an
    error); a glow on the sky side, a smear, or an albedo change within the PSF depth that varies along the limb moves
    the centre (``docs/validation/constants.md#traced-asymmetry``).  As in Hausman's (1978) specification test, the
    difference of two estimators that agree when the model holds.  ``None`` if either fit fails."""

    out = []
    try:
        for level in (0.3, 0.7):
            tr = trace_limb(img, ell, lit_dir, half, 8.0, level=level, shade=shade)
            e = fit_traced(tr, ell)
            out.append(np.array([e[0][0], e[0][1]]))
    except TooManyOutliersError:
        return None
    d = out[0] - out[1]
    return (float(d[0]), float(d[1]), 0.0)


__all__ = ["GLOW_TILT_MAX_PHASE_DEG", "patchy_geometry", "ray_geometry"]
