r"""Checks 1-5 of the Aerospace 2015 paper (§3) as typed exceptions, and where each is raised.

=========  ==========================================  ==============================================
check      condition                                   raised by (exception)
=========  ==========================================  ==============================================
no body    no contrast in the frame (all-black, all-    :func:`jaxlimb.imaging.detect_body`
           white, pure noise)                          (:class:`~jaxlimb.errors.NoBodyError`)
1          too small (diameter < 10 px) / too big      prior: :func:`jaxlimb.imaging.check_prior`;
           (radius > frame half-diagonal, or the lit   image: :func:`jaxlimb.imaging.detect_body`;
           region fills > 90 % of the frame)           fit: :func:`check_size` (``TooSmallError``,
                                                       ``TooBigError``)
1/2        new moon / crescent too thin (p_i < 3 px    prior / image (``TooThinError``)
           from the hints; < 4 px measured)
2          too few candidates after the box filter     gradient front end (``TooManyOutliersError``)
3          too few RANSAC inliers; too many residual   front ends; :func:`jaxlimb.pipeline.sphere.annulus`
           outliers in the annulus                     outlier pass (``TooManyOutliersError``)
3/4        RANSAC / Taubin radius outside the prior    front ends (``RadiusInconsistentError``);
           band; the refined radius too                :func:`check_radius_prior`
4          body centre far outside the imager          :func:`check_center_in_field`
                                                       (:class:`CenterOutOfFieldError`)
3/4        the lit limb arc in the frame is shorter   :func:`check_lit_arc`
           than ``MIN_LIT_ARC_DEG`` (cropped body      (:class:`~jaxlimb.errors.ArcTooShortError`)
           whose Sun-facing side is out of frame)
5          no convergence within ``max_steps``          :func:`jaxlimb.pipeline.sphere.annulus` fits
                                                       (``ConvergenceError``)
5          the fit jumped away from the Taubin circle  :func:`check_jump` (``JumpError``)
=========  ==========================================  ==============================================

Check 5, the jump test (decision: the paper gives no number).  The fitted limb is compared
with the front end's (Taubin) circle *on the arc that was fitted*: with
:math:`u(\psi)` the unit direction at polar angle :math:`\psi`, the radial displacement of the
limb is :math:`\delta(\psi) = (\hat r_{fit} - \hat r_0) + (c_{fit} - c_0)\cdot u(\psi)` (first
order in the centre change); the test fails when :math:`\max_\psi |\delta(\psi)| >
X = \max(2, \Delta r/2)` px.  Measuring the displacement on the fitted arc (instead of the
centre change) keeps short arcs -- cropped bodies, crescents, where centre and radius of the
Taubin circle are strongly correlated -- from failing spuriously, while a fit that locked on
a terminator, a star or the annulus edge moves the limb by several px and fails.  Half the
annulus half-width is where the limb leaves the well-sampled middle of the annulus.

Lit-arc check (decision; the papers' cropped-target section, Aerospace 2015 §3.4, detects the
crop but sets no limit).  Only the limb facing the Sun is an edge of the body; beyond the horns
the edge is the terminator (and the range prior, good to ~5 %, fixes the radius only to px).
A circle fitted to an arc of total angle :math:`\Theta` has a centre error
:math:`g(\Theta)\,\sigma_r/\sqrt{N}` for ``N`` points of radial noise :math:`\sigma_r`, with the
geometric dilution (least squares on ``1, cos, sin`` over the arc) ``g`` = 2.0 for the full circle,
3.5 for a half circle, 6.9 at 120 deg, 11.6 at 90 deg, 25 at 60 deg, 44 at 45 deg, 98 at 30 deg
(~ :math:`1/\Theta^2`); smooth along-arc limb biases (the sigmoid's limb bias changes with the
brightness along the arc) are amplified the same way.  Measured on rendered cropped Moons
(``benchmarks/locate_accuracy.py``, category ``cropped``): the fit's own centre sigma is
0.2-0.35 px at 30-45 deg and errors reach 0.5-0.7 px, 11-25 px sigma at 7 deg; from ~70 deg
on the errors are below ~0.3 px.  ``MIN_LIT_ARC_DEG = 60``: below it the frame does not
measure the centre to a fraction of a pixel, and :class:`~jaxlimb.errors.ArcTooShortError` is
raised instead of returning a wrong answer.  The arc is the angular span (360 deg less the
largest gap) of the pixels kept for the fit -- inside the frame, on the lit side, in angular
bins that show a lit edge -- seen from the fitted centre.  The physical limb profile (the
default with a known Sun direction) has no along-arc limb bias to amplify: on 60 cropped frames
(3 seeds, arcs measured with the check off) its centre error is <= 0.15 px from 43 deg on
(0.18-0.60 px at 28-37 deg, px below 20 deg) against 0.25-0.68 px for the sigmoid at 44-50 deg,
hence ``MIN_LIT_ARC_PROFILE_DEG = 45`` for it; a profile fit that is rejected falls back to the
sigmoid and to 60 deg.

Check 4, centre in the field: the limb must be visible, so the body centre cannot be farther
from the frame than its radius; we raise when the distance of the centre from the frame
rectangle exceeds ``radius + 2 px`` -- a circle found that does not touch the frame.
"""

from __future__ import annotations

import math

import numpy as np

from .._validate import check_center_sigma
from ..errors import (ArcTooShortError, CenterTooUncertainError, CheckFailed, JumpError, RadiusInconsistentError,
                      TooBigError, TooSmallError)
from ..imaging.crop import MIN_DIAMETER_PX

#: Shortest lit limb arc (deg) measured with the sigmoid (module docstring, lit-arc check).
MIN_LIT_ARC_DEG = 60.0
#: Shortest lit limb arc (deg) measured with the physical limb profile (module docstring).
MIN_LIT_ARC_PROFILE_DEG = 45.0
#: Check 3: a pixel whose residual exceeds this many robust sigmas (1.4826 MAD) is an outlier (stars, hot pixels) ...
OUTLIER_SIGMA = 5.0
#: ... and more outliers than this fraction of the pixels fitted fails the check.
MAX_OUTLIER_FRACTION = 0.2
#: A fit whose edge blur (Gaussian PSF sigma, px) exceeds this is not a limb (:func:`check_edge_width`).
MAX_PSF_SIGMA_PX = 5.0


class CenterOutOfFieldError(CheckFailed):
    """Check 4: the estimated body centre lies so far outside the imager that its limb cannot be in it."""

    check = "center_out_of_field"


def max_limb_displacement(center0, radius0: float, center1, radius1: float, angles: np.ndarray) -> float:
    """``max |delta(psi)|`` over ``angles`` (module docstring, Check 5).

    Parameters
    ----------
    center0 : (float, float)
        Centre ``(row, col)`` of the front end's (Taubin) circle (px).
    radius0 : float
        Its radius (px).
    center1 : (float, float)
        Centre of the fitted circle (px).
    radius1 : float
        Its radius (px).
    angles : np.ndarray (n,)
        Polar angles (rad, ``atan2(d_row, d_col)``) of the fitted pixels.

    Returns
    -------
    float
        Largest radial displacement of the limb on the arc (px); with no angles, ``|dr| + |dc|`` (the bound
        over all directions).
    """
    ang = np.asarray(angles, dtype=float)
    if ang.size == 0:
        return abs(radius1 - radius0) + float(np.hypot(center1[0] - center0[0], center1[1] - center0[1]))
    dcr, dcc = float(center1[0]) - float(center0[0]), float(center1[1]) - float(center0[1])
    delta = (radius1 - radius0) + dcr * np.sin(ang) + dcc * np.cos(ang)
    return float(np.max(np.abs(delta)))


def jump_threshold(dr: float) -> float:
    """The Check-5 threshold ``X = max(2, dr/2)`` px (module docstring).

    Parameters
    ----------
    dr : float
        Annulus half-width (px).

    Returns
    -------
    float
        The largest limb displacement accepted (px).
    """
    return max(2.0, 0.5 * float(dr))


def check_jump(center0, radius0: float, center1, radius1: float, angles: np.ndarray, threshold: float) -> float:
    """Check 5: raise :class:`~jaxlimb.errors.JumpError` if the fitted limb moved more than ``threshold``.

    Parameters
    ----------
    center0 : (float, float)
        Centre ``(row, col)`` of the front end's circle (px).
    radius0 : float
        Its radius (px).
    center1 : (float, float)
        Centre of the fitted circle (px).
    radius1 : float
        Its radius (px).
    angles : np.ndarray (n,)
        Polar angles (rad) of the fitted pixels (:func:`max_limb_displacement`).
    threshold : float
        Limit (px), :func:`jump_threshold`.

    Returns
    -------
    float
        The displacement (px) when the check passes.
    """
    disp = max_limb_displacement(center0, radius0, center1, radius1, angles)
    if not math.isfinite(disp) or disp > threshold:
        raise JumpError(
            f"Check 5: the sigmoid fit moved the limb by up to {disp:.3g} px from the front end's circle "
            f"(centre ({center0[0]:.2f}, {center0[1]:.2f}), radius {radius0:.2f}) to centre "
            f"({center1[0]:.2f}, {center1[1]:.2f}), radius {radius1:.2f}; the limit is {threshold:.3g} px"
        )
    return disp


def arc_span_deg(angles: np.ndarray) -> float:
    """Angular span (deg) of polar ``angles`` (rad): 360 deg less the largest gap between them.

    Parameters
    ----------
    angles : np.ndarray (n,)
        Polar angles (rad), any range.

    Returns
    -------
    float
        The span in degrees (0 for fewer than two angles).
    """
    a = np.sort(np.mod(np.asarray(angles, dtype=float), 2.0 * math.pi))
    if a.size < 2:
        return 0.0
    gaps = np.diff(np.concatenate([a, [a[0] + 2.0 * math.pi]]))
    return float(math.degrees(2.0 * math.pi - float(gaps.max())))


def check_lit_arc(angles: np.ndarray, min_arc_deg: float = MIN_LIT_ARC_DEG, halfangle: float | None = None,
                  cause: str | None = None) -> float:
    """Raise :class:`~jaxlimb.errors.ArcTooShortError` if the fitted pixels span less than ``min_arc_deg``.

    Parameters
    ----------
    angles : np.ndarray (n,)
        Polar angles (rad) of the fitted pixels about the circle centre.
    min_arc_deg : float
        Shortest arc accepted (deg; module docstring, lit-arc check).
    halfangle : float, optional
        Half-angle (rad) of the lit-side window; the limit is never more than 90 % of the window
        (``2 halfangle``), so that a body whose whole lit limb is in the frame always passes.
    cause : str, optional
        Why the arc is short, for the message (default: a cropped body facing the Sun out of the frame).

    Returns
    -------
    float
        The span (deg).
    """
    span = arc_span_deg(angles)
    limit = float(min_arc_deg)
    if halfangle is not None:
        limit = min(limit, 0.9 * math.degrees(2.0 * float(halfangle)))
    if not span >= limit:
        raise ArcTooShortError(
            f"the lit limb in the frame spans {span:.3g} deg, below min_lit_arc_deg = {limit:.3g} deg: a circle "
            "through so short an arc does not fix the centre and radius to a fraction of a pixel ("
            + (cause or "cropped body whose Sun-facing side is outside the frame") + ")"
        )
    return span


def check_radius_prior(radius: float, band: tuple[float, float], source: str = "prior") -> None:
    """Check 4 on the refined radius: it must lie in the prior's band ``[lo, hi]`` (px).

    Parameters
    ----------
    radius : float
        Refined radius (px).
    band : (float, float)
        ``(lo, hi)`` radius band of the prior (px).
    source : str
        Name of the prior, for the message.

    Raises
    ------
    RadiusInconsistentError
        The radius is outside the band.
    """
    lo, hi = band
    if not (lo <= radius <= hi):
        raise RadiusInconsistentError(
            f"Check 4: the refined radius {radius:.4g} px is outside the range [{lo:.4g}, {hi:.4g}] px "
            f"expected from the {source} prior"
        )


def check_size(radius: float, shape: tuple[int, int], min_diameter_px: float = MIN_DIAMETER_PX,
               arc_deg: float | None = None) -> None:
    """Check 1 on the measurement: diameter below ``min_diameter_px`` or radius above the half-diagonal.

    Parameters
    ----------
    radius : float
        Measured radius (px).
    shape : (int, int)
        Frame ``(rows, cols)``.
    min_diameter_px : float
        Smallest diameter accepted (px).
    arc_deg : float, optional
        The fitted arc in the frame (deg); makes the too-big message say what is missing: a limb arc *is*
        visible, but a free circle larger than the frame through it is not checked by anything; the camera and
        a range prior fix the circle's size and the arc is then measured
        (:class:`jaxlimb.pipeline.sphere.predicted.PredictedLimbSphere`).

    Raises
    ------
    TooSmallError, TooBigError
        The measured size fails Check 1.
    """
    if 2.0 * radius < min_diameter_px:
        raise TooSmallError(
            f"Check 1: measured apparent diameter {2 * radius:.3g} px is below min_diameter_px = {min_diameter_px:g} px"
        )
    half_diag = 0.5 * math.hypot(*shape)
    if radius > half_diag and arc_deg is not None:
        raise TooBigError(
            f"Check 1: measured radius {radius:.4g} px exceeds the frame half-diagonal {half_diag:.4g} px: only a "
            f"{arc_deg:.0f}-deg arc of the limb is in the frame, and a free circle through it is not checked; give "
            "the camera and hints range_prior_km and the body (or --kernels) so that the arc is measured with the "
            "size the range predicts"
        )
    if radius > half_diag:
        raise TooBigError(
            f"Check 1: measured radius {radius:.4g} px exceeds the frame half-diagonal {half_diag:.4g} px "
            "(the body fills the image)"
        )


def check_center_in_field(center_rc, radius: float, shape: tuple[int, int], margin_px: float = 2.0) -> None:
    """Check 4: the distance of the centre from the frame rectangle must not exceed ``radius + margin_px``.

    Parameters
    ----------
    center_rc : (float, float)
        Body centre ``(row, col)`` (px).
    radius : float
        Radius (px).
    shape : (int, int)
        Frame ``(rows, cols)``; the rectangle spans ``[-0.5, rows - 0.5] x [-0.5, cols - 0.5]``.
    margin_px : float
        Slack added to the radius (px).

    Raises
    ------
    CenterOutOfFieldError
        The circle does not touch the frame.
    """
    r, c = float(center_rc[0]), float(center_rc[1])
    R, C = shape
    dr = max(0.0, -0.5 - r, r - (R - 0.5))
    dc = max(0.0, -0.5 - c, c - (C - 0.5))
    dist = math.hypot(dr, dc)
    if not math.isfinite(dist) or dist > radius + margin_px:
        raise CenterOutOfFieldError(
            f"Check 4: the centre ({r:.4g}, {c:.4g}) lies {dist:.4g} px outside the {R}x{C} frame, farther than "
            f"the radius {radius:.4g} px + {margin_px:g} px: its limb cannot be in the image"
        )


__all__ = [
    "MIN_LIT_ARC_DEG",
    "MIN_LIT_ARC_PROFILE_DEG",
    "ArcTooShortError",
    "CenterOutOfFieldError",
    "arc_span_deg",
    "check_lit_arc",
    "check_center_in_field",
    "check_jump",
    "check_radius_prior",
    "check_size",
    "jump_threshold",
    "max_limb_displacement",
]


# ====================================================================== a fit is physical or it is a failure
class NonPhysicalFitError(CheckFailed):
    """The fit converged to a limb no camera sees: the body darker than the sky (amplitude of the wrong
    sign, ``ymax <= ymin``), an edge blur (PSF sigma, or the sigmoid's ``k``) outside the plausible range,
    or non-finite numbers."""

    check = "non_physical_fit"


def check_levels(ymax: float, ymin: float, what: str) -> None:
    """The lit body must be brighter than the sky: ``ymax > ymin`` (DN), both finite.

    Parameters
    ----------
    ymax, ymin : float
        Inside and outside levels of the fitted edge (DN).
    what : str
        The fit's name, for the message.

    Raises
    ------
    NonPhysicalFitError
        The levels are not finite or not in that order.
    """
    if not (math.isfinite(ymax) and math.isfinite(ymin) and ymax > ymin):
        raise NonPhysicalFitError(
            f"the {what} fit is not a lit limb: inside level ymax = {ymax:.6g} DN is not above the sky level "
            f"ymin = {ymin:.6g} DN (amplitude of the wrong sign)")


def check_edge_width(psf_sigma_px: float, what: str) -> None:
    """The edge's Gaussian-equivalent PSF sigma (px) must lie in ``[0, MAX_PSF_SIGMA_PX]``.

    Parameters
    ----------
    psf_sigma_px : float
        Fitted edge blur (px).
    what : str
        The fit's name, for the message.

    Raises
    ------
    NonPhysicalFitError
        The blur is not finite or outside the range.
    """
    if not (math.isfinite(psf_sigma_px) and 0.0 <= psf_sigma_px <= MAX_PSF_SIGMA_PX):
        raise NonPhysicalFitError(
            f"the {what} fit's edge blur (Gaussian PSF sigma {psf_sigma_px:.4g} px) is outside the plausible range "
            f"[0, {MAX_PSF_SIGMA_PX:g}] px: the fit followed something else than a limb")


__all__ += ["CenterTooUncertainError", "NonPhysicalFitError", "check_center_sigma", "check_edge_width",
            "check_levels"]
