r"""Stages 3-4 of :func:`jaxlimb.pipeline.locate` for a round limb (sphere, disc): the limb pixels (an
annulus on the lit side, Aerospace 2015 §5) and the edge fit (the circular sigmoid, Eq. 16 of the
illuminated-ellipsoid paper, with ``k`` estimated or held), then Checks 5, 1 and 4 on the fitted circle.

The lit-side window and the annulus' angular bins are the *band/selection* stage: everything
that decides which pixels are the limb (and so keeps a glow, a terminator or the dark limb out
of the fit) is in :func:`limb_pixels`; the fits that follow only use the pixels it returns.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import ArcTooShortError
from ..checks import (
    MIN_LIT_ARC_DEG,
    MIN_LIT_ARC_PROFILE_DEG,
    check_center_in_field,
    check_jump,
    check_lit_arc,
    check_radius_prior,
    check_size,
    jump_threshold,
    max_limb_displacement,
)
from ..frame import arc_angles, frame_mask, min_diameter_px
from ..sigmoid import LOGISTIC_TO_GAUSS
from ..stages import AnnulusSelection, EdgeFit, Frame, LimbPixels, RefineResult
from .annulus import ANGULAR_BIN_DEG, annulus_halfwidth, ANNULUS_MIN_PX, lit_halfangle, select_annulus
from .fits import fit_circle_annulus

#: Widen the annulus when it is narrower than this many Gaussian-equivalent edge sigmas.
EDGE_SIGMAS = 4.5


#: Narrowest annulus half-width (px) for a thin crescent: +-3 px cover +-2.5 sigma of a 1.2 px Gaussian PSF.
CRESCENT_MIN_DR = 3.0
#: Half-angle (deg) of lit limb about the Sun direction a thin crescent's annulus is narrowed to reach.
CRESCENT_HALF_DEG = 40.0


def crescent_halfwidth(phase: float | None, radius: float, dr: float, min_arc_deg: float) -> float:
    """The annulus half-width (px) for a thin crescent: ``dr`` unless the lit band is too thin for it.

    :func:`~jaxlimb.pipeline.sphere.annulus.lit_halfangle` keeps the directions where the terminator lies at least
    ``dr + 2`` px inside the limb.  A thin crescent (``R (1 - |cos phase|) < dr + 2`` at the Sun direction; e.g.
    benchmark row ``jpeg`` 5, 145 deg phase, R ~ 40 px: a 7 px thick band for a 6 px annulus) then has no
    usable direction at all although its whole lit limb is in the frame.  When the usable arc is below
    ``min_arc_deg`` the inner band is narrowed to the PSF's width: the half-width is lowered (never below
    ``CRESCENT_MIN_DR``) to the one for which the lit limb is usable over ``CRESCENT_HALF_DEG`` about the Sun
    direction (terminator at ``R/sqrt(cos^2 psi/cos^2 phase + sin^2 psi)`` along the ray at ``psi``,
    :mod:`jaxlimb.pipeline.sphere.annulus` rule 2).

    Parameters
    ----------
    phase : float or None
        Phase angle (rad); ``None`` or gibbous: ``dr`` unchanged.
    radius, dr : float
        Initial radius and annulus half-width (px).
    min_arc_deg : float
        Shortest lit arc accepted (deg).

    Returns
    -------
    float
        Half-width of the inner band (px), ``CRESCENT_MIN_DR <= result <= dr`` when narrowed.
    """
    if phase is None or phase <= math.pi / 2 or dr <= CRESCENT_MIN_DR:
        return dr
    if 2.0 * math.degrees(lit_halfangle(phase, radius, dr)) >= min_arc_deg:
        return dr  # usable as it is (narrowing further takes benchmark row airy 1 from 0.017 to 0.069 px)
    psi = math.radians(CRESCENT_HALF_DEG)
    c2 = max(math.cos(phase) ** 2, 1e-300)
    thick = radius * (1.0 - 1.0 / math.sqrt(math.cos(psi) ** 2 / c2 + math.sin(psi) ** 2))
    return float(min(dr, max(CRESCENT_MIN_DR, thick - 2.0)))


def lit_window(frame: Frame, cand: Any, dr: float) -> tuple[tuple[float, float] | None, float, float | None]:
    """The lit side: ``(direction, half-angle, phase)`` from the Sun direction, else from the image.

    Parameters
    ----------
    frame : Frame
    cand : LimbCandidates
        The front end's circle, lit direction and arc, and its prior (image phase) in ``info``.
    dr : float
        Annulus half-width (px), for the crescent's horn margin.

    Returns
    -------
    direction : (float, float) or None
        Unit ``(d_row, d_col)`` toward the lit side; ``None``: all round (half-angle ``pi``).
    half : float
        Half-angle of the window (rad).
    phase : float or None
        Phase angle (rad) from the hints' Sun direction, else from the image; ``None``: unknown.
    """
    prior = cand.info.get("prior")
    phase = frame.phase(cand.center_rc) if frame.sun_known else (prior.phase_rad if prior is not None else None)
    direction = cand.lit_direction
    if direction is None:
        return None, math.pi, phase
    if frame.sun_known:
        return direction, lit_halfangle(phase, cand.radius, dr), phase
    # Sun unknown: the arc of the front end's points, but never more than the lit half-circle of the
    # phase measured on the image (more is the dark limb / terminator)
    ph_img = prior.phase_rad if prior is not None else None
    half = min(cand.lit_halfangle + math.radians(2.0), lit_halfangle(ph_img, cand.radius, dr))
    return direction, half, phase


def limb_pixels(frame: Frame, cand: Any, physical_profile: bool) -> LimbPixels:
    """Stage 3: the annulus ``r_hat +- dr`` on the lit side (:func:`~jaxlimb.pipeline.sphere.annulus.select_annulus`),
    and the lit-arc check before any fit (cropped body, Sun-facing side out of the frame): on the front end's
    limb points (:func:`check_front_end_arc`), then on the annulus.

    Parameters
    ----------
    frame : Frame
    cand : LimbCandidates
        The front end's circle and lit direction.
    physical_profile : bool
        The lunar-Lambert profile will be fitted: its shorter lit-arc limit applies.

    Returns
    -------
    LimbPixels
        The annulus and its window; a thin crescent's band ``[r - dr_in, r + dr]`` as its half-width and shift.

    Raises
    ------
    ArcTooShortError
        Too little lit limb (a crescent too thin, a cropped body); :class:`InitialCircleOffError` when the lit-side
        annulus is in the frame but its bins lack a lit edge.
    """
    opt = frame.opt
    dr = dr_in = annulus_halfwidth(cand.radius, cand.residual_rms)
    min_arc = float(opt.min_lit_arc_deg) if opt.min_lit_arc_deg is not None else (
        MIN_LIT_ARC_PROFILE_DEG if physical_profile else MIN_LIT_ARC_DEG)
    if frame.sun_known:
        dr_in = crescent_halfwidth(frame.phase(cand.center_rc), cand.radius, dr, min_arc)
    direction, half, phase = lit_window(frame, cand, dr_in)
    if direction is not None and (half <= 0.0 or (dr_in < dr and 2.0 * math.degrees(half) < min_arc)):
        raise ArcTooShortError(thin_crescent_message(phase, cand.radius, dr_in, half, min_arc))
    check_front_end_arc(cand, min_arc, half)
    # a thin crescent: the band [r - dr_in, r + dr] (inside: the lit band; outside: the sky, always there),
    # i.e. half-width (dr_in + dr)/2 about r + (dr - dr_in)/2, never widened (the terminator would enter it)
    shift, h = 0.5 * (dr - dr_in), 0.5 * (dr + dr_in)
    sel = select_annulus(frame.img, cand.center_rc, cand.radius + shift, h, direction, half, frame_mask(frame))
    cause = _short_annulus_cause(sel, min_arc, half)
    try:
        check_lit_arc(sel.angles(), min_arc, half, cause)
    except ArcTooShortError as e:
        raise (InitialCircleOffError(str(e)) if cause is not None and frame.sun_known else e) from None
    return LimbPixels(sel, h, direction, half, phase, min_arc, h if dr_in < dr else math.inf, shift)


class InitialCircleOffError(ArcTooShortError):
    """The lit-arc check failed although the Sun-facing annulus is in the frame: its angular bins lack a lit edge
    at the limb (:func:`_short_annulus_cause`), so the front end's circle may be off the limb rather than the lit
    limb short; :func:`jaxlimb.pipeline.locate` then tries the other front end (``front_end_fallback``).  Held-out
    frame ``defocus`` 1 of ``benchmarks/families.py --seed 2027`` (a 39.5 px Moon at 144 deg phase, defocus disc
    PSF): the gradient front end's 58 points lie on two edges, 35 of them 3 px inside the limb on the crescent's
    rising inner slope and 23 on the limb, and their Taubin circle has a 46 px radius 9 px off the centre; 8 of
    17 bins kept, 44 deg of lit limb.  The scan lines' circle: 40.9 px, 0.7 px off."""


def thin_crescent_message(phase: float | None, radius: float, dr: float, half: float = 0.0,
                          min_arc_deg: float | None = None) -> str:
    """The failure when too little of the lit limb is usable: the crescent is thinner than the annulus (even the
    narrowed one of :func:`crescent_halfwidth`) over all but ``2 half`` (rad) of it; the limb is in the frame.
    E.g. 150 deg at 40 px (``tests/pipeline/test_crescent.py``): a 37 deg window, on which the circle sigmoid
    wandered to a 250 px radius and stopped as ``no_convergence``.

    Parameters
    ----------
    phase : float or None
        Phase angle (rad).
    radius, dr : float
        Radius and annulus half-width (px).
    half : float
        Usable half-angle of the lit limb (rad).
    min_arc_deg : float, optional
        The arc limit, quoted when given.

    Returns
    -------
    str
        The message of the :class:`~jaxlimb.errors.ArcTooShortError`.
    """
    ph = math.degrees(phase) if phase is not None else float("nan")
    thick = radius * (1.0 - abs(math.cos(phase))) if phase is not None else float("nan")
    arc = f", a {2.0 * math.degrees(half):.0f} deg arc below min_lit_arc_deg = {min_arc_deg:.0f} deg" if (
        half > 0.0 and min_arc_deg is not None) else ""
    return (f"the crescent is too thin to measure: at phase {ph:.1f} deg the lit band is {thick:.1f} px thick at the "
            f"Sun direction (radius {radius:.1f} px) and thins toward the horns; where it is under the "
            f"{dr + 2.0:.1f} px the annulus needs inside the limb (half-width {dr:.1f} px + 2) the limb is not used, so "
            f"the usable half-angle of the lit limb comes out {math.degrees(half):.0f} deg{arc}")


def _short_annulus_cause(sel: AnnulusSelection, min_arc_deg: float, half: float) -> str | None:
    """Why the annulus' lit arc may be short, for :func:`~jaxlimb.pipeline.checks.check_lit_arc`: ``None`` (the
    default, a cropped body) unless the angular bins with pixels in the frame span the arc needed, in which case
    the bins were dropped for want of a lit edge at the limb (rules 3-4 of :mod:`jaxlimb.pipeline.sphere.annulus`)."""
    width = max(ANGULAR_BIN_DEG, math.degrees(4.0 / max(sel.radius, 1e-9)))
    in_frame = min(sel.n_bins * width, 2.0 * math.degrees(half))
    if in_frame < min(min_arc_deg, 0.9 * 2.0 * math.degrees(half)):
        return None
    return (f"about {in_frame:.0f} deg of the lit-side annulus are in the frame, but only {sel.n_bins_kept} of its "
            f"{sel.n_bins} angular bins show a lit edge at the limb: a crescent thinner than the annulus, or an "
            "initial circle too far from the limb")


def check_front_end_arc(cand: Any, min_arc_deg: float, half: float) -> float | None:
    """The lit-arc check (:func:`~jaxlimb.pipeline.checks.check_lit_arc`) on the front end's limb points, seen
    from its circle's centre, before any iterative fit; ``None`` (no check) without points.

    Why: the annulus check that follows sees the pixels of the annulus about the front end's circle, and a
    circle through a short arc is itself poorly determined.  Benchmark row ``cropped`` 2
    (``benchmarks/families.py``; a 54 px Moon 23 px beyond the bottom edge, Sun toward the bottom edge): the
    front end's 32 points lie on 17 deg of lit limb (24-34 deg of it are in the frame), its Taubin circle has a
    radius of 77 px for 54, and the annulus about that circle spans 120 deg (3 of 33 bins with an edge); the
    circle sigmoid then wanders (no convergence in 100-150 steps, an 86 px jump at 400), so without this check
    the frame fails as ``no_convergence`` instead of ``arc_too_short``.  On every other Moon frame of the
    benchmark the front end's points span 66 deg or more (118 deg or more outside the ``cropped`` family).

    Parameters
    ----------
    cand : LimbCandidates
        ``points_rc`` ``(m, 2)`` and the circle centre.
    min_arc_deg : float
        Shortest arc accepted (deg).
    half : float
        Half-angle of the lit-side window (rad).

    Returns
    -------
    float or None
        The points' arc (deg).
    """
    pts = cand.points_rc
    if len(pts) < 2:
        return None
    return check_lit_arc(arc_angles(np.asarray(pts, float), cand.center_rc), min_arc_deg, half)


def _reselect(frame: Frame, pix: LimbPixels, circ: RefineResult, dr: float) -> tuple[LimbPixels, RefineResult]:
    p = circ.fit.params
    sel = select_annulus(frame.img, (float(p.r0), float(p.c0)), float(p.radius) + pix.shift, dr, pix.direction,
                         pix.half, frame_mask(frame))
    pix = LimbPixels(sel, dr, pix.direction, pix.half, pix.phase, pix.min_arc_deg, pix.dr_max, pix.shift)
    return pix, fit_circle_annulus(sel, frame.opt)


def edge_fit(frame: Frame, pix: LimbPixels) -> EdgeFit:
    """Stage 4: the circular sigmoid on the annulus; the annulus widened to ``EDGE_SIGMAS`` edge sigmas
    when the fitted edge is broader, and re-centred on the fitted circle when the limb moved by more than
    half a pixel (the annulus was built on the front end's circle); the lit-arc check on the fitted pixels.

    The model is the circular sigmoid (CSF, Eq. 16 of the illuminated-ellipsoid paper; Aerospace 2015 §6).

    Parameters
    ----------
    frame : Frame
    pix : LimbPixels
        The annulus (:func:`limb_pixels`).

    Returns
    -------
    EdgeFit
        The fit, its (possibly re-selected) annulus, whether it was widened / re-centred, and the arc (deg).
    """
    opt = frame.opt
    circ = fit_circle_annulus(pix.sel, opt)
    widened = recentered = False
    if opt.estimate_k:
        need = EDGE_SIGMAS * LOGISTIC_TO_GAUSS / max(float(circ.fit.params.k), 1e-6)
        cap = min(max(ANNULUS_MIN_PX, 0.5 * pix.sel.radius), pix.dr_max)
        if need > 1.05 * pix.dr and pix.dr < cap:
            pix, circ = _reselect(frame, pix, circ, min(cap, need))
            widened = True
    p = circ.fit.params
    if max_limb_displacement(pix.sel.center_rc, pix.sel.radius - pix.shift, (float(p.r0), float(p.c0)), float(p.radius),
                             pix.sel.angles()) > 0.5:
        pix, circ = _reselect(frame, pix, circ, pix.dr)
        recentered = True
    p = circ.fit.params
    arc = check_lit_arc(arc_angles(circ.coords, (p.r0, p.c0)), pix.min_arc_deg, pix.half)
    frame.mark("refine")
    return EdgeFit(circ, pix, widened, recentered, arc)


def check_edge(frame: Frame, cand: Any, edge: EdgeFit) -> EdgeFit:
    """Checks 5 (jump from the front end's circle), 1 (size), 3/4 (radius in the prior's band) and 4
    (centre in the field) on the fitted circle; returns ``edge`` with the jump and its limit.

    Parameters
    ----------
    frame : Frame
    cand : LimbCandidates
        The front end's circle and prior.
    edge : EdgeFit
        The unchecked fit of :func:`edge_fit`.

    Returns
    -------
    EdgeFit
        ``edge`` with ``jump_px`` and ``jump_limit_px`` set.
    """
    thr = jump_threshold(edge.pixels.dr)
    # a thin crescent's band lies ``shift`` outside the front end's circle: the jump is from the band's middle
    jump = check_jump(cand.center_rc, cand.radius + edge.pixels.shift, edge.center_rc, edge.radius, edge.pixels.sel.angles(), thr)
    check_size(edge.radius, frame.img.shape, min_diameter_px(frame), edge.arc_deg)
    prior = cand.info.get("prior")
    if prior is not None:
        check_radius_prior(edge.radius, prior.radius_range, prior.source)
    check_center_in_field(edge.center_rc, edge.radius, frame.img.shape)
    return EdgeFit(edge.circ, edge.pixels, edge.widened, edge.recentered, edge.arc_deg, jump, thr)


def edge_report(frame: Frame, cand: Any, edge: EdgeFit) -> dict[str, Any]:
    """The intermediate values of the round limb's first stages, for ``extras``.

    Parameters
    ----------
    frame : Frame
    cand : LimbCandidates
    edge : EdgeFit

    Returns
    -------
    dict
        Initial circle, circle fit, annulus, lit window, phase, bins, outliers, jump, prior source.
    """
    circ, pix = edge.circ, edge.pixels
    prior = cand.info.get("prior")
    return {
        "initial_circle": {"center_rc": list(cand.center_rc), "radius_px": cand.radius, "rms_px": cand.residual_rms},
        "circle_fit": {"center_rc": list(edge.center_rc), "radius_px": edge.radius},
        "annulus_px": pix.dr, "annulus_widened": edge.widened, "annulus_recentered": edge.recentered,
        "lit_arc_deg": edge.arc_deg,
        "lit_direction_rc": list(pix.direction) if pix.direction is not None else None,
        "lit_halfangle_deg": math.degrees(pix.half), "sun_direction_known": frame.sun_known,
        "phase_deg": math.degrees(pix.phase) if pix.phase is not None else None,
        "n_angular_bins": [pix.sel.n_bins_kept, pix.sel.n_bins],
        "n_outliers": int(circ.n_outliers), "jump_px": edge.jump_px,
        "jump_limit_px": edge.jump_limit_px if math.isfinite(edge.jump_limit_px) else None,
        "levels_normalized": circ.data.weights is not None, "k_estimated": bool(frame.opt.estimate_k),
        "prior_source": prior.source if prior is not None else None,
    }


__all__ = ["EDGE_SIGMAS", "check_front_end_arc", "edge_report", "check_edge", "edge_fit", "limb_pixels", "lit_window"]
