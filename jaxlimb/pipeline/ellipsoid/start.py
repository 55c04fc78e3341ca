"""The ellipsoid's first stages: its candidates (the shared front end, or the disc and the range prior when that
fails on cloud edges) and its limb pixels (the position prior, the lit window and the initial ellipse, traced
against the sky: :mod:`jaxlimb.pipeline.ellipsoid.trace`)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ...errors import ArcTooShortError, GeometryError, RadiusInconsistentError, TooManyOutliersError
from ...geometry.conic import ellipse_change, ellipse_signed_distance
from ...imaging.candidates import LimbCandidates
from ...imaging.prior import sun_direction_image
from ..frame import candidates
from ..stages import EllipsePixels, Frame
from .model import EllipsoidModel
from .shading import RayShading
from .trace import trace_limb
from .trace_fit import fit_traced


#: The lunar-Lambert ``L`` of the shading under an albedo-patchy limb's traced rays (:class:`RayShading`): 0, Lambert
#: (the Earth's clouds and surface; not measurable from the rays, which the flatness test selects).
PATCHY_SHADING_L = 0.0


#: Without the Sun direction (no shading model for the trace's flatness test), the smallest share of the wide trace's
#: rays kept for the trace to start the fit: on a Lambert limb near zero phase (the sunlit Earth from deep space) the
#: brightness rises inward as the square root of the depth and the plain test keeps 2-4 % of the rays, those beside a
#: bright cloud; an ellipse through them ran 7 px off (``epic_earth_20220910.jpg``), the band fit about the front
#: end's ellipse is within 1 px.  (Cf. :meth:`~jaxlimb.pipeline.ellipsoid.trace.TracedLimb.patchy`, whose rule for
#: one ray in ten is the same.)
MIN_UNSHADED_SHARE = 0.1


def ellipsoid_candidates(body: EllipsoidModel, frame: Frame) -> Any:
    """Stage "candidates" of the ellipsoid: the shared front end; when it fails on the limb's size or outliers (its
    circle on cloud edges) the disc's outermost lit pixel and the range prior's radius (:func:`blob_candidates`)
    start the trace instead; so they do when the front end's radius lies outside the range prior's 1-sigma band
    (``Prior.radius_uncertainty_frac``: its 3-sigma RANSAC band lets circles on cloud edges through).

    Parameters
    ----------
    body : EllipsoidModel
        The body (limb radius for the fallback).
    frame : Frame
        The prepared frame.

    Returns
    -------
    LimbCandidates
        The front end's candidates, or the fallback start (no points, ``lit_halfangle = pi/2``).

    Raises
    ------
    RadiusInconsistentError, TooManyOutliersError
        The front end failed and no fallback start is available (no range prior or Sun direction).
    """
    try:
        cand = candidates(frame)
    except (RadiusInconsistentError, TooManyOutliersError):
        start = blob_candidates(body, frame)
        if start is None:
            raise
        return start
    prior = cand.info.get("prior")
    if (prior is not None and prior.expected_radius_px
            and abs(cand.radius / prior.expected_radius_px - 1.0) > prior.radius_uncertainty_frac):
        # a circle on cloud edges that RANSAC's 3-sigma band let through (61 and 168 px for 124-127 px Earths,
        # benchmarks/families.py Earth ``clouds`` 3, 5): the trace cannot reach the limb from it (it searches
        # 20 % of the radius); start from the disc and the prior's radius instead
        start = blob_candidates(body, frame)
        if start is not None:
            return replace(start, info={**start.info, "prior": prior})
    return cand


def ellipse_pixels(body: EllipsoidModel, frame: Frame, cand: Any) -> EllipsePixels:
    """Stage "limb pixels" of the ellipsoid: the position prior (range prior, else the radius of the candidates'
    circle), the lit window (the half-circle about the Sun's image direction less ``arc_margin_deg`` at each horn;
    without the Sun, the front end's arc, at most a half-circle: it ends where the front end found no lit edge, and a
    margin there would leave a full-disc Earth's free ellipse a third of its lit limb: 2-4 px off the EPIC product
    centres of ``../shared/data/epic``, 0.5-0.8 px with the whole arc) and the initial ellipse (shape predicted with
    a known attitude) traced against the sky (:func:`traced_start`).

    Parameters
    ----------
    body : EllipsoidModel
        The body.
    frame : Frame
        The prepared frame (camera, hints).
    cand : LimbCandidates
        The candidates' circle and lit arc.

    Returns
    -------
    EllipsePixels
        Observer position prior (km, camera frame), range prior (km), lit window ``(d_row, d_col)`` and half-angle
        (rad), the start ellipse ``((r0, c0), (a, b), theta)`` (px, rad) and its trace (or ``None``).

    Raises
    ------
    GeometryError
        The range prior puts the observer inside the body.
    ArcTooShortError
        Less than 10 deg of lit arc is left.
    """
    cam, h, eo = frame.cam, frame.hints, body.eo
    c_rc = np.array(cand.center_rc, float)
    rl = body.equatorial_km + body.atmosphere_km
    D0 = h.range_prior_km or rl / math.sin(math.atan(cand.radius / cam.focal_px))
    if not D0 > rl:
        raise GeometryError(f"range prior {D0:.6g} km puts the observer inside the Earth (radius {rl:.6g} km)")
    p0 = -D0 * cam.los(c_rc)  # observer relative to the body centre, camera frame
    lit_dir, half = cand.lit_direction, cand.lit_halfangle
    sd = sun_direction_image(h.sun_dir_camera, cam, tuple(c_rc)) if h.sun_dir_camera is not None else None
    if sd is not None:  # the lit half-circle, less the margin at its ends: the horns
        lit_dir, half = sd, math.pi / 2 - math.radians(eo.arc_margin_deg)
    elif lit_dir is not None:  # the front end's arc: its ends are where it found lit edges, not horns
        half = min(half, math.pi / 2)
    if lit_dir is not None:
        if half <= math.radians(5):
            left = f"left after {eo.arc_margin_deg:g} deg at each horn " if sd is not None else "the front end found "
            raise ArcTooShortError(f"the lit limb arc {left}spans {max(0.0, 2 * math.degrees(half)):.3g} deg "
                                   "(at least 10 deg needed): too short for the ellipse")
    rho, th = (0.999, 0.0) if body.R is None else body.predicted_shape(cam, -p0)
    a0 = cand.radius / math.sqrt(rho)
    half = half if lit_dir is not None else math.pi
    ell = ((float(c_rc[0]), float(c_rc[1])), (a0, a0 * rho), th)
    ell, tr = traced_start(frame.img, ell, lit_dir, half, eo.band_px, ray_shading(body, frame))
    return EllipsePixels(p0, float(D0), lit_dir, half, ell, tr)


def blob_candidates(body: EllipsoidModel, frame: Frame) -> Any:
    """A start without the front end (:meth:`~jaxlimb.pipeline.ellipsoid.body.Ellipsoid.candidates`): the radius
    ``f tan(asin(Re / D))`` of the range prior ``D`` and the centre ``R`` px behind the brightest-side extreme of the
    disc (the pixel above the sky by 5 noise sigma farthest toward the Sun's image direction).

    Parameters
    ----------
    body : EllipsoidModel
        The body (equatorial radius and limb height).
    frame : Frame
        The prepared frame: camera, ``range_prior_km`` and ``sun_dir_camera`` are needed.

    Returns
    -------
    LimbCandidates or None
        Centre ``(row, col)`` and radius (px), the Sun's image direction as the lit side; ``None`` without a
        camera, range prior or Sun, with the prior inside the body, or when no disc of 50 px or more is found.
    """

    cam, h, img = frame.cam, frame.hints, np.asarray(frame.img, float)
    if cam is None or h is None or not h.range_prior_km or h.sun_dir_camera is None:
        return None
    rl = body.equatorial_km + body.atmosphere_km
    if not h.range_prior_km > rl:
        return None
    R = cam.focal_px * math.tan(math.asin(rl / h.range_prior_km))
    from scipy.ndimage import label

    dark = img[img <= np.percentile(img, 70)]  # the sky (the disc covers < 30 % of a frame it fits in)
    sky, noise = float(np.median(dark)), max(float(np.std(dark)), 1e-6 * float(np.ptp(img)), 1e-12)
    lab, n = label(img > sky + 5.0 * noise)
    if n == 0:
        return None
    sizes = np.bincount(lab.ravel())[1:]
    rr, cc = np.nonzero(lab == 1 + int(np.argmax(sizes)))  # the disc: the largest bright component
    if rr.size < 50:
        return None
    c_mid = (float(np.median(rr)), float(np.median(cc)))
    sd = sun_direction_image(h.sun_dir_camera, cam, c_mid)
    if sd is None:
        return None
    proj = rr * sd[0] + cc * sd[1]
    far = proj >= np.percentile(proj, 99.9)
    p = np.array([np.median(rr[far]), np.median(cc[far])])
    c = p - R * np.asarray(sd, float)
    return LimbCandidates(np.zeros((0, 2)), (float(c[0]), float(c[1])), float(R), math.nan, tuple(sd), math.pi / 2,
                          "range prior + disc extreme", {"fallback": "front end failed"})


def ray_shading(body: EllipsoidModel, frame: Frame) -> Any:
    """The uniform disc's shading for the trace's flatness test
    (:class:`~jaxlimb.pipeline.ellipsoid.shading.RayShading`, lunar-Lambert :data:`PATCHY_SHADING_L`).

    Parameters
    ----------
    body : EllipsoidModel
        The body (unused).
    frame : Frame
        The frame (camera, Sun direction).

    Returns
    -------
    RayShading or None
        The shading model; ``None`` without the Sun direction.
    """
    sun = frame.hints.sun_dir_camera
    return None if sun is None else RayShading(frame.cam, tuple(float(x) for x in sun), PATCHY_SHADING_L)


def wide_trace(img: np.ndarray, ell: tuple, lit_dir, half: float, shade: Any) -> Any:
    """The start's wide trace (20 % of the radius deep, at least 12 px) -- with the shading-flattened flatness test
    (:class:`~jaxlimb.pipeline.ellipsoid.shading.RayShading`) when the shading explains the plain test's rejections
    (a uniform disc would fail it on half the rays or more,
    :meth:`~jaxlimb.pipeline.ellipsoid.shading.RayShading.dark_share`: a dark Lambert limb near zero phase) and the
    flattened test keeps more rays, traced about ``ell`` or, when that keeps fewer than the plain test, about the
    plain rays' own fit.  Every other frame keeps its plain trace: the flattened trace is not tested for a glow
    (:func:`~jaxlimb.pipeline.ellipsoid.patchy.ray_geometry`).

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image.
    ell : tuple
        The start ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    lit_dir : tuple of float or None
        Direction ``(d_row, d_col)`` of the lit side; ``None``: all round.
    half : float
        Half-angle (rad) of the lit window.
    shade : RayShading or None
        The uniform disc's shading (``None``: plain test only).

    Returns
    -------
    TracedLimb
        The trace kept.
    """

    search = max(12.0, 0.2 * ell[1][0])
    tr = trace_limb(img, ell, lit_dir, half, search)
    if shade is None or shade.dark_share(ell, tr.angles) < 0.5:
        return tr
    flat = trace_limb(img, ell, lit_dir, half, search, shade=shade)
    if flat.ok.sum() <= tr.ok.sum() and tr.ok.sum() >= 20:
        # the shading is placed on the reference ellipse: about a start 1 px off (on a cloud edge) the flattened
        # trace kept 24 rays of 321, about the plain rays' own fit 270 (benchmarks/earth_mottled.py map 15, 10 deg)
        flat = trace_limb(img, fit_traced(tr, ell), lit_dir, half, search, shade=shade)
    return flat if flat.ok.sum() > max(tr.ok.sum(), 20) else tr


def traced_start(img: np.ndarray, ell: tuple, lit_dir, half: float, band: float,
                  shade: Any = None) -> tuple[tuple, Any]:
    """The initial ellipse from the limb against the sky (:mod:`jaxlimb.pipeline.ellipsoid.trace`): a wide trace
    about the front end's ellipse (it may lie on cloud edges: the search reaches 20 % of the radius;
    :func:`wide_trace`), a fit, a narrow trace about it and a second fit.  Without the shading model (no Sun
    direction) a wide trace keeping fewer than :data:`MIN_UNSHADED_SHARE` of its rays is not used.  A front-end ellipse within 1 px (median)
    of the traced points, whose rays' fit also lies within 1 px, is kept (a fit of few traced rays may run off).

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image.
    ell : tuple
        The front end's ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    lit_dir : tuple of float or None
        Direction ``(d_row, d_col)`` of the lit side; ``None``: all round.
    half : float
        Half-angle (rad) of the lit window.
    band : float
        The band's half-width (px); the narrow trace searches ``max(6, 2 band)`` px.
    shade : RayShading or None
        The uniform disc's shading for the wide trace's flatness test.

    Returns
    -------
    ell : tuple
        The start ellipse ``((r0, c0), (a, b), theta)``.
    trace : TracedLimb or None
        The narrow trace (its per-ray levels normalise the band; it carries the wide trace's ``shade``); ``None``
        when too few rays have a flat inside or the fit ran off (then ``ell`` is the front end's).
    """

    try:
        tr = wide_trace(img, ell, lit_dir, half, shade)
        if shade is None and tr.ok.mean() < MIN_UNSHADED_SHARE:
            return ell, None
        narrow = max(6.0, 2.0 * band)
        on_limb = bool(tr.ok.sum()) and np.median(np.abs(ellipse_signed_distance(tr.points[tr.ok], ell))) < 1.0
        if on_limb and tr.ok.sum() < 20:
            return ell, trace_limb(img, ell, lit_dir, half, narrow, shade=tr.shade)
        e1 = fit_traced(tr, ell)
        if on_limb and ellipse_change(ell, e1) < 1.0:
            # the front end's ellipse is on the traced limb: it stays the start (the trace only gives the levels).
            # (Not when the rays' own fit lies elsewhere: on a full-disc cloudy Earth the front end's circle, 10 px
            # inside on cloud edges, had half the wide trace's crossings within 1 px and the rays' fit 0.3 px from the
            # limb; benchmarks/earth_full_disc.py ``clouds`` 0.)
            return ell, trace_limb(img, ell, lit_dir, half, narrow, shade=tr.shade)
        tr = trace_limb(img, e1, lit_dir, half, narrow, shade=tr.shade)
        e2 = fit_traced(tr, e1)
    except TooManyOutliersError:  # too few rays with a flat inside (a bright glow's foot): the front end's ellipse
        return ell, None
    if not (abs(e2[1][0] / ell[1][0] - 1.0) < 0.2 and math.dist(e2[0], ell[0]) < 0.2 * ell[1][0]):
        return ell, None  # the robust fit ran off (a few rays on a short arc): the front end's ellipse
    return e2, tr


__all__ = ["blob_candidates", "ellipse_pixels", "ellipsoid_candidates", "ray_shading", "traced_start", "wide_trace"]
