"""The ellipsoid's edge fit (Mortari et al. 2016 §V-C and Fig. 2): the elliptical sigmoid with interior ramp on the
band, the range iteration and the predicted shape, repeated while the prediction moves the ellipse; then the
patchy limb's second estimate and the checks."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import equinox as eqx
import numpy as np

from ...errors import JumpError, TooManyOutliersError
from ...fitting import fit
from ...geometry.conic import ellipse_change, ellipse_points, ellipse_signed_distance
from ...models import ELLIPSE, ELLIPSE_RAMP
from ..checks import check_center_in_field, check_radius_prior, check_size, jump_threshold
from ..frame import min_diameter_px
from ..options import EllipsoidOptions
from ..stages import EllipsePixels, EllipsoidEdge, Frame, RefineResult
from .band import band_data, edge_start, first_levels
from .model import as_ellipse, EllipsoidModel, MAX_REFITS, position, REFIT_TOL_PX
from .patchy import patchy_geometry


def ellipsoid_edge(body: EllipsoidModel, frame: Frame, cand: Any, pix: EllipsePixels) -> EllipsoidEdge:
    """Stage "edge fit" of the ellipsoid: the ramp ESF loop (:func:`edge_loop`), the rays' estimate on a patchy limb
    with the attitude known, then Checks 5 (jump), 1 (size), 3/4 (radius in the prior's band) and the centre in
    the field on the fitted ellipse.

    Parameters
    ----------
    body : EllipsoidModel
        The body.
    frame : Frame
        The prepared frame.
    cand : Any
        The front end's candidates (initial circle, prior).
    pix : EllipsePixels
        Position prior, lit window and start ellipse.

    Returns
    -------
    EllipsoidEdge
        The edge fit with the jump and its limit.

    Raises
    ------
    JumpError, TooSmallError, RadiusInconsistentError, CenterOutOfFieldError, TooManyOutliersError
        A failed check (:mod:`jaxlimb.errors`).
    """
    edge = edge_loop(body, frame, pix)
    if pix.patchy and not body.free:
        edge = patchy_geometry(body, frame, edge)
    (r0, c0), (a, b), _ = edge.fitted
    # the jump first (as for the sphere, edge.check_edge): a fit that collapsed from a 400 px circle to a point
    # was reported as a body too small to measure (a full-disc cloudy Earth, benchmarks/earth_full_disc.py)
    edge = check_ellipse_jump(frame, cand, edge, body.eo)
    check_size(0.5 * (a + b), frame.img.shape, min_diameter_px(frame))
    prior = cand.info.get("prior")
    if prior is not None:
        check_radius_prior(0.5 * (a + b), prior.radius_range, prior.source)
    check_center_in_field((r0, c0), a, frame.img.shape)
    return edge


def edge_loop(body: EllipsoidModel, frame: Frame, pix: EllipsePixels) -> EllipsoidEdge:
    """Steps 2-4 of :mod:`jaxlimb.pipeline.ellipsoid`: the elliptical sigmoid fit (Mortari et al. 2016 §V-C) on the
    band, the range iteration and the predicted shape (Eq. 2-9), refitted while the prediction moves the ellipse by
    more than :data:`~jaxlimb.pipeline.ellipsoid.model.REFIT_TOL_PX`; on a patchy limb with the attitude known a band
    fit that does not converge returns its start (``band_converged=False``) for the rays' fit instead of raising.
    Fewer than 50 pixels in the band is a :class:`~jaxlimb.errors.TooManyOutliersError`.

    Parameters
    ----------
    body : EllipsoidModel
        The body: ``free`` fits ``rho, theta``, else they are predicted and held.
    frame : Frame
        The prepared frame.
    pix : EllipsePixels
        Position prior, lit window and start ellipse.

    Returns
    -------
    EllipsoidEdge
        The last fit, its data, ellipse ``((r0, c0), (a, b), theta)``, position (km) and fit history.
    """
    eo, cam, img = body.eo, frame.cam, frame.img
    model = ELLIPSE_RAMP if eo.interior_ramp else ELLIPSE
    fixed = () if body.free else ("rho", "theta")
    if pix.patchy and eo.interior_ramp:  # per-ray levels and a flat interior (limb_trace): a plain step
        fixed = fixed + tuple(n for n in ("g", "g2", "h1", "h2", "h3", "h4") if n not in fixed)
    ell, p, prev, res, hist = pix.ellipse, pix.p0, None, None, []
    rays = pix.patchy and not body.free  # a band fit that does not converge is not the end (patchy_geometry)
    for it in range(MAX_REFITS):
        data = band_data(img, ell, eo.band_px, pix)
        pts, z = data.coords, data.z
        if pts.shape[0] < 50:
            raise TooManyOutliersError(f"only {pts.shape[0]} pixels in the lit limb band (need >= 50)")
        init = edge_start(eo, ell, res.params if res is not None else None,
                           first_levels(img, pts, z, ell, eo.band_px) if res is None else (0.0, 0.0))
        res = fit(model, pts, z, init, body.solver(frame), fixed=fixed, weights=data.weights, throw=not rays)
        if not bool(res.converged):  # a patchy limb's band fit lost on cloud edges: the rays answer (patchy_geometry)
            hist.append({"fit": it + 1, "converged": False, "fit_steps": int(res.n_steps)})
            final = RefineResult(eqx.tree_at(lambda x: x.params, res, init), data, 0,
                                 tuple(n for n in model.param_names if n not in res.free))
            return EllipsoidEdge(final, pix, pix.ellipse, position(body, cam, pix.ellipse, p)[0], hist, 0.0, 0.0,
                                 band_converged=False)
        fitted = as_ellipse(res.params)
        p, info = position(body, cam, fitted, p)
        hist.append({"fit": it + 1, "range_km": float(np.linalg.norm(p)), "range_iterations": info["iterations"],
                     "fit_steps": int(res.n_steps)})
        if body.free:
            done, ell = prev is not None and ellipse_change(prev, fitted) < REFIT_TOL_PX, fitted
            prev = fitted
        else:  # the shape predicted at the new position; refit only if it moves the ellipse noticeably
            rho, th = body.predicted_shape(cam, -p)
            ell = (fitted[0], (fitted[1][0], fitted[1][0] * rho), th)
            done = ellipse_change(fitted, ell) < REFIT_TOL_PX
        if done:
            break
    frame.mark("refine")
    final = RefineResult(res, data, 0, tuple(n for n in model.param_names if n not in res.free))
    return EllipsoidEdge(final, pix, fitted, p, hist, 0.0, 0.0)


def check_ellipse_jump(frame: Frame, cand: Any, edge: EllipsoidEdge, eo: EllipsoidOptions) -> EllipsoidEdge:
    """Check 5: the fitted ellipse must lie within ``max(2, band/2) + (a - b)`` px of the front end's circle on
    the fitted arc (the circle cannot follow the ellipse's out-of-roundness ``a - b``); with a trace, of the
    traced start ellipse on the lit arc.

    Parameters
    ----------
    frame : Frame
        The frame (unused).
    cand : Any
        The front end's candidates (``center_rc``, ``radius``).
    edge : EllipsoidEdge
        The edge fit.
    eo : EllipsoidOptions
        ``band_px`` sets the threshold.

    Returns
    -------
    EllipsoidEdge
        ``edge`` with ``jump_px`` (the largest distance, px) and ``jump_limit_px``.

    Raises
    ------
    JumpError
        The fit moved the limb farther than the limit.
    """

    pts = edge.final.coords
    if edge.pixels.trace is not None:  # the initial conic is the traced ellipse, not the front end's circle

        e0 = edge.pixels.ellipse
        ang = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
        on_circle = ellipse_points(e0[0], e0[1], e0[2], ang)
        arc = np.abs(np.angle(np.exp(1j * (np.arctan2(on_circle[:, 0] - e0[0][0], on_circle[:, 1] - e0[0][1])
                                          - np.arctan2(*(edge.pixels.lit_dir or (0.0, 1.0))))))) <= edge.pixels.half
        on_circle = on_circle[arc]
    else:
        ang = np.arctan2(pts[:, 0] - cand.center_rc[0], pts[:, 1] - cand.center_rc[1])
        on_circle = np.column_stack([cand.center_rc[0] + cand.radius * np.sin(ang),
                                     cand.center_rc[1] + cand.radius * np.cos(ang)])
    disp = float(np.max(np.abs(ellipse_signed_distance(on_circle, edge.fitted)))) if pts.size else math.inf
    (_, _), (a, b), _ = edge.fitted
    thr = jump_threshold(eo.band_px) + (a - b)
    if not disp <= thr:
        raise JumpError(f"Check 5: the elliptical fit moved the limb by up to {disp:.3g} px from the front end's "
                        f"circle (limit {thr:.3g} px)")
    return replace(edge, jump_px=disp, jump_limit_px=thr)


__all__ = ["check_ellipse_jump", "edge_loop", "ellipsoid_edge"]
