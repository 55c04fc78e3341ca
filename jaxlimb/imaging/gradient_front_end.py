r"""Gradient front end: §4-5 of the Aerospace 2015 paper.

Pipeline (:func:`gradient_front_end`):

1. validate the image; :func:`~jaxlimb.imaging.crop.detect_body` (no-body test,
   Eq. 10 threshold, region of interest, image Checks 1-2);
2. the prior (§3): from hints + camera (:func:`~jaxlimb.imaging.prior.prior_from_hints`,
   Check 1) or, without them, measured on the image
   (:func:`~jaxlimb.imaging.prior.prior_from_image`); the settings N, s, d_max (Eq. 15-17);
3. the gradient of the ROI: four-point central differences with one Richardson
   extrapolation (Eq. 18-22, :func:`richardson_gradient`);
4. the N strongest gradient pixels, refined to sub-pixel position along the
   gradient direction (parabola through three samples);
5. the box-based outlier filter (§4.2, :mod:`jaxlimb.imaging.boxfilter`); Check 2 (failing, steps 3-5 once more
   with the gradient kept in the band about the lit region's outline);
6. RANSAC with index rotation (§4.3, :func:`jaxlimb.conics.ransac_circle`); Check 3;
7. Taubin's fit (Eq. 26-35) on the inliers after a final 3-sigma trim; Check 4.

Decisions:

* Richardson extrapolation (Eq. 20-22) is applied to the two derivative
  *components* (linear in the image, one 9-tap kernel per axis,
  ``(16 k_h - k_2h)/15``), then the magnitude (Eq. 19) is taken.  The paper
  extrapolates the magnitude; both cancel the h^4 term where the gradient is
  non-zero, but the component form is a plain linear filter (one OpenCV call per
  axis) and has no bias at low gradient.
* Sub-pixel refinement of the candidate pixels (step 4) is not in the paper; it
  removes the +-0.5 px quantisation of pixel positions from the Taubin initial
  estimate (the 0.5 px target needs it at ~1 px blur).
* Final trim: after RANSAC, points with residual above
  ``max(TRIM_MIN_PX, 3 * 1.4826 * MAD)`` are dropped before the last Taubin fit
  (removes terminator points that fall within the loose RANSAC distance near
  the horns).
* Lit side only (Sun direction known): the trimmed inliers more than 90 deg from the
  projected Sun direction are dropped and Taubin refitted (:func:`_lit_side_only`): there
  the edge is the terminator, up to ``R (1 - cos phase)`` inside the limb, and when the
  Sun-facing side of a cropped body is outside the frame those points dominate the
  circle and shorten its radius.
* Outline retry (not in the paper): a disc whose interior edges are sharper than its limb (clouds against ocean,
  a hazy or limb-darkened edge) has its N strongest gradients inside, and the box filter keeps a handful of them
  (Check 2).  The limb lies on the outline of the lit region found by thresholding (contours of the Eq. (10)
  region, as ``cv2.findContours`` gives it), so steps 3-5 are repeated with the gradient zeroed outside a band of
  ``max(8 px, 6 %)`` of the region's radius about its outline (:func:`~.front_end_common.outline_band`); only
  a frame whose first attempt failed takes this path, and only with the region inside the frame.
* Check 4 ("radius inconsistent with the expected value") uses the prior's band
  (:attr:`~jaxlimb.imaging.prior.Prior.radius_range`: ``p_r (1 -/+ 3 u)`` for
  hints; for a prior measured on the image see
  :func:`~jaxlimb.imaging.prior.prior_from_image`).
* Check 3 has two outcomes: when RANSAC restricted to the prior's radius band
  fails but an unrestricted RANSAC finds a circle, the radius is inconsistent
  with the prior (:class:`~jaxlimb.errors.RadiusInconsistentError`); otherwise
  there are too many outliers (:class:`~jaxlimb.errors.TooManyOutliersError`).
* The paper's Check 4 also rejects a centre "out of the imager and too far from
  the optical axis"; a circle through points inside the frame has its centre
  within ``radius + half-diagonal`` of the frame centre, so with the radius band
  this adds nothing and is not a separate error (``info["center_in_image"]``
  reports it).
* Speed: the ROI is converted to float32 and differentiated in float32 (it only
  *selects* pixels; their positions and all fits are float64).  A 1944x2592
  frame costs ~25 ms of CPU (body radius 150-300 px), ~50 ms when the body
  fills the frame (``tests/imaging/bench_front_ends.py``).
* Pre-smoothing (automatic): a Gaussian of 1 px is
  applied before differentiation when the noise exceeds 2 % of the body's
  contrast (the Richardson kernel amplifies noise; the paper smooths its
  synthetic images with a 3x3 mask).  Smoothing is symmetric across the edge,
  so it does not move the circle.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from ..conics.ransac import RansacOptions, ransac_circle
from ..conics.taubin import circle_residuals, fit_circle_taubin
from ..errors import CheckFailed, ConfigError, TooManyOutliersError
from ..geometry.camera import Camera
from .boxfilter import box_filter
from .candidates import LimbCandidates, lit_arc
from .crop import BodyRegion, DetectOptions, detect_body, nearest_fill
from .front_end_common import (check_radius, check_region_inside, outline_band, radius_band, region_outside_fraction,
                               resolve_prior, valid_zone)
from .gradient import richardson_gradient, strongest_pixels, subpixel_refine
from .io import validate_image
from .prior import Hints, Prior, PriorOptions, derived_settings, ransac_tests, sun_direction_image


#: Automatic pre-smoothing: a Gaussian of 1 px before differentiation when the noise exceeds this fraction of the
#: body's contrast (module docstring).
PRESMOOTH_NOISE_FRAC = 0.02
#: Check 3: fewest RANSAC inliers ...
MIN_INLIERS = 10
#: ... and fewest as a fraction of the box filter's survivors.
MIN_INLIER_FRACTION = 0.15
#: Floor (px) of the final 3-sigma trim of the inliers.
TRIM_MIN_PX = 1.0
#: A circle leaving more than this fraction of the lit region outside it lies on interior edges
#: (:func:`_interior_circle_retry`): a limb circle leaves none of it (a glow's few per cent at most).
INTERIOR_CIRCLE_FRAC = 0.5
#: Check 3 of a variegated body: largest fraction of the detected region outside the fitted circle
#: (:func:`check_region_inside`).
MAX_REGION_OUTSIDE_FRAC = 0.05


@dataclass(frozen=True)
class GradientOptions:
    """Settings of :func:`gradient_front_end`.

    Attributes
    ----------
    min_points_box
        Check 2: fewest candidates left after the box filter (>= 3).
    detect
        :class:`~jaxlimb.imaging.crop.DetectOptions`.
    prior
        :class:`~jaxlimb.imaging.prior.PriorOptions`.
    """

    min_points_box: int = 10
    detect: DetectOptions = field(default_factory=DetectOptions)
    prior: PriorOptions = field(default_factory=PriorOptions)

    def __post_init__(self) -> None:
        if not (isinstance(self.min_points_box, int) and self.min_points_box >= 3):
            raise ConfigError(f"GradientOptions.min_points_box must be an integer >= 3, got {self.min_points_box!r}")


def _lit_side_only(pts: np.ndarray, inl: np.ndarray, fit, offset_rc, hints: Hints, camera: Camera | None,
                   phase_rad: float, min_points: int, band: tuple[float, float] | None = None):
    """Drop the inliers on the Sun-averted side of the circle and refit Taubin (decision, module docstring).

    With the Sun direction known, the limb is lit exactly on the half-circle facing the Sun; the edge
    on the other side is the terminator, ``R (1 - |cos(phase)|)`` px inside the limb at the anti-Sun
    point.  RANSAC's loose distance (5 % of ``p_r``) accepts those points when the lit arc is short
    (cropped bodies whose Sun-facing side is outside the frame), and the Taubin circle through limb +
    terminator is then pulled inward by up to that depth (16 px measured on a 120 px Moon at 31 deg).
    Points more than 90 deg from the projected Sun direction are dropped (two passes: the centre
    moves), unless the terminator is within half a pixel of the limb (nearly full) or fewer than
    ``min_points`` would remain or the circle of the lit points alone leaves the prior's radius band
    ``band`` (a lit arc too short to fix a circle: the lit-arc check downstream,
    :func:`jaxlimb.pipeline.checks.check_lit_arc`, then decides).
    """
    if fit.radius * (1.0 - abs(math.cos(phase_rad))) < 0.5:
        return inl, fit, 0
    n0 = int(inl.sum())
    inl0, fit0 = inl, fit
    for _ in range(2):
        center = (fit.center_rc[0] + offset_rc[0], fit.center_rc[1] + offset_rc[1])
        sun_rc = sun_direction_image(hints.sun_dir_camera, camera, center if camera is not None else None)
        if sun_rc is None:
            return inl, fit, 0
        v = pts - np.asarray(fit.center_rc)
        lit = (v[:, 0] * sun_rc[0] + v[:, 1] * sun_rc[1]) >= 0.0
        keep = inl & lit
        if keep.sum() < min_points or keep.sum() == inl.sum():
            break
        inl = keep
        fit = fit_circle_taubin(pts[inl])
    if band is not None and not (band[0] <= fit.radius <= band[1]):
        return inl0, fit0, 0
    return inl, fit, n0 - int(inl.sum())


def _outward_bright_to_dark(cand: np.ndarray, diag: dict, region: BodyRegion, offset_rc) -> np.ndarray:
    """A sky brighter than the body's darkest parts: only the lit limb's candidates, whose bright-to-dark
    normal (the box filter's) points away from the lit region's centroid.  The shadowed limb against the
    sky (the opposite polarity, the sky the brighter side) is a limb too, but not the one the lit-limb
    sigmoid models."""
    out = cand.astype(np.float64) + np.asarray(offset_rc, float) - np.asarray(region.centroid_rc, float)
    return np.einsum("ij,ij->i", out, diag["normal_rc"]) > 0


def _timings(t0: float, t_detect: float, t_grad: float, t_box: float, t_fit: float) -> dict[str, float]:
    """Seconds per stage of the gradient front end, and in all (to now) since ``t0``."""
    times = {"detect": t_detect - t0, "gradient": t_grad - t_detect, "box": t_box - t_grad, "ransac_taubin": t_fit - t_box}
    return {**times, "total": time.perf_counter() - t0}


def _stage_info(pri, st, win, region, n_box, res, inl, n_dark, fit, shape) -> dict:  # type: ignore[no-untyped-def]
    """The gradient front end's stage counts and settings (:attr:`LimbCandidates.info`)."""
    return {
        "prior": pri,
        "settings": st,
        "roi": win.roi,
        "region": region,
        "n_candidates": int(win.candidates.shape[0]),
        "n_after_box": n_box,
        "n_after_ransac": res.n_inliers,
        "n_final": int(inl.sum()),
        "n_dark_side_dropped": n_dark,
        "ransac_tests": res.n_tests,
        "ransac_dmax": st.ransac_dmax,
        "presmooth_sigma": win.presmooth_sigma,
        "masked_retry": win.near_mask,
        "outline_retry": win.outline,
        "residual_max": fit.max_abs,
        "cropped": region.crop,
        "center_in_image": bool(0 <= fit.center_rc[0] + win.offset_rc[0] <= shape[0] - 1
                                and 0 <= fit.center_rc[1] + win.offset_rc[1] <= shape[1] - 1),
    }


def gradient_front_end(
    image: np.ndarray, prior: Prior | None = None, *, hints: Hints | None = None, camera: Camera | None = None,
    options: GradientOptions | None = None, mask: np.ndarray | None = None,
) -> LimbCandidates:
    """Limb points and initial circle by gradient + box filter + RANSAC + Taubin (§3-5).

    Parameters
    ----------
    image
        2-D grey image ``[row, col]`` (any numeric dtype).
    prior
        A :class:`~jaxlimb.imaging.prior.Prior`; if ``None`` it is computed from
        ``hints`` (+ ``camera``) or measured on the image.
    hints, camera
        Navigation hints and camera (optional).
    options
        :class:`GradientOptions`.
    mask
        Validity mask (``True`` = measured; :class:`jaxlimb.imaging.formats.Frame`): the gradient
        within the kernel's reach (4 px + 3 pre-smoothing sigmas) of an invalid pixel is zeroed, so
        a missing line or a readout window's edge is never a limb candidate.

    Returns
    -------
    LimbCandidates
        ``front_end="gradient"``; ``info`` holds the stage counts, settings and timings.

    Raises
    ------
    ImageContentError
        Invalid image array.
    NoBodyError, TooSmallError, TooBigError, TooThinError
        Check 1 (prior or image).
    TooManyOutliersError
        Checks 2-3: too few candidates after the box filter or RANSAC.
    RadiusInconsistentError
        Check 4: the Taubin radius is inconsistent with the prior.
    """
    opt = options or GradientOptions()
    t0 = time.perf_counter()
    img = validate_image(image, reject_constant=False, as_float64=False)
    region = detect_body(nearest_fill(img, mask), opt.detect)
    t_detect = time.perf_counter()
    pri = resolve_prior(img, region, prior, hints, camera, opt.prior)
    st = derived_settings(pri, opt.prior)
    band = radius_band(pri, region)
    win = _gradient_window(img, region, st, mask)
    t_grad = time.perf_counter()
    win, pts, n_box = _outline_retry(img, region, st, opt, mask, win)
    t_box = time.perf_counter()
    inl, fit, res, n_dark = _ransac_taubin(pts, n_box, win.offset_rc, pri, st, band, hints, camera, opt)
    if not (win.outline or region.dark_surface or region.touches_border):
        fits = (win, pts, n_box, inl, fit, res, n_dark)
        win, pts, n_box, inl, fit, res, n_dark = _interior_circle_retry(img, region, st, opt, mask, fits,
                                                                       (pri, band, hints, camera))
    t_fit = time.perf_counter()
    check_radius(fit.radius, pri, band)
    info = _stage_info(pri, st, win, region, n_box, res, inl, n_dark, fit, img.shape)
    info["timings_s"] = _timings(t0, t_detect, t_grad, t_box, t_fit)
    return _limb_candidates(pts[inl], fit, win.offset_rc, region, pri, hints, camera, info)


def _limb_candidates(pts: np.ndarray, fit, offset_rc, region: BodyRegion, pri: Prior, hints: Hints | None,  # noqa: ANN001
                     camera: Camera | None, info: dict) -> LimbCandidates:
    """The front end's answer from the final circle ``fit`` of the inliers ``pts`` (ROI frame): Check 3 of a
    variegated body's region, the lit arc (about the Sun's image direction when known)."""
    points_full = pts + np.asarray(offset_rc, dtype=np.float64)
    center = (fit.center_rc[0] + offset_rc[0], fit.center_rc[1] + offset_rc[1])
    check_region_inside(center, float(fit.radius), region, MAX_REGION_OUTSIDE_FRAC)
    sun_rc = pri.sun_dir_rc
    if hints is not None and hints.sun_dir_camera is not None:
        sun_rc = sun_direction_image(hints.sun_dir_camera, camera, center if camera is not None else None)
    lit_dir, half = lit_arc(points_full, center, sun_rc) if sun_rc is not None else lit_arc(points_full, center)
    return LimbCandidates(points_rc=points_full, center_rc=(float(center[0]), float(center[1])), radius=float(fit.radius),
                          residual_rms=float(fit.rms), lit_direction=lit_dir, lit_halfangle=half, front_end="gradient",
                          info=info)


@dataclass(frozen=True)
class _GradientWindow:
    """The region of interest of :func:`gradient_front_end` after step 3: its (pre-smoothed) pixels,
    their gradient, the strongest candidates and the validity of each pixel."""

    roi: tuple[int, int, int, int]
    smoothed: np.ndarray
    g: np.ndarray
    gr: np.ndarray
    gc: np.ndarray
    candidates: np.ndarray
    valid: np.ndarray | None
    presmooth_sigma: float
    near_mask: bool = False
    outline: bool = False

    @property
    def offset_rc(self) -> tuple[int, int]:
        return self.roi[0], self.roi[2]


def _outline_retry(img: np.ndarray, region: BodyRegion, st, opt: GradientOptions, mask: np.ndarray | None,
                   win: _GradientWindow) -> tuple[_GradientWindow, np.ndarray, int]:
    """Step 5 (:func:`_masked_retry`); when Check 2 fails, steps 3-5 again with the gradient kept only in the band about
    the lit region's outline (:func:`outline_band`, ``info["outline_retry"]``): a limb lies on the outline of the lit
    region, and a disc whose interior edges are sharper than its limb (cloud against ocean on a full-disc Earth, a
    soft hazy limb) gives the ``N`` strongest gradients all inside (the box filter then keeps a few of 1500: the EPIC
    frames of ``../shared/data/epic``).  Not for a region cut by the frame: its outline is partly the frame's edge (and a
    terminator with the lit limb outside the frame is no limb).  If that fails too, the first failure stands.  Returns
    the window used and its points."""
    try:
        return _masked_retry(img, region, st, opt, mask, win)
    except TooManyOutliersError as err:
        if region.dark_surface or region.touches_border:  # in the band already; an outline partly the frame's edge
            raise
        first = err
    band = _gradient_window(img, region, st, mask, outline=True)
    try:
        return (band, *_box_filtered_points(band, region, st, opt))
    except TooManyOutliersError:
        raise first from None


def _interior_circle_retry(img: np.ndarray, region: BodyRegion, st, opt: GradientOptions, mask: np.ndarray | None,
                           fits: tuple, prior: tuple) -> tuple:
    """Steps 3-7 once more in the band about the lit region's outline (:func:`_outline_retry`) when the circle of
    ``fits`` (``win, pts, n_box, inl, fit, res, n_dark``) leaves more than :data:`INTERIOR_CIRCLE_FRAC` of the lit
    region outside it: no limb circle does, a circle through interior edges does (cloud edges of a full-disc Earth:
    a 158 px circle in a 399 px disc).  The retry's answer when it succeeds, else ``fits`` unchanged."""
    win, fit = fits[0], fits[4]
    center = (fit.center_rc[0] + win.offset_rc[0], fit.center_rc[1] + win.offset_rc[1])
    if region_outside_fraction(center, float(fit.radius), region) <= INTERIOR_CIRCLE_FRAC:
        return fits
    pri, band, hints, camera = prior
    try:
        o = _gradient_window(img, region, st, mask, outline=True)
        pts, n_box = _box_filtered_points(o, region, st, opt)
        return (o, pts, n_box, *_ransac_taubin(pts, n_box, o.offset_rc, pri, st, band, hints, camera, opt))
    except CheckFailed:
        return fits


def _masked_retry(img: np.ndarray, region: BodyRegion, st, opt: GradientOptions, mask: np.ndarray | None,
                  win: _GradientWindow) -> tuple[_GradientWindow, np.ndarray, int]:
    """Step 5 on ``win``; when Check 2 fails because the lit body reaches the invalid pixels (:func:`_masked_limb_note`:
    a product whose off-body pixels are blanked 1-2 px outside the limb, ``resampled_hmi.fits``), step 3-5 again on the
    frame with each invalid pixel holding its nearest valid one (no step at the mask's edge) and only the invalid pixels
    themselves excluded (``info["masked_retry"]``); if that fails too, the first failure stands.  Returns the window
    used and its points."""
    try:
        return (win, *_box_filtered_points(win, region, st, opt))
    except TooManyOutliersError as err:
        if not _masked_limb_note(win, region):
            raise
        first = err
    near = _gradient_window(img, region, st, mask, near_mask=True)
    try:
        return (near, *_box_filtered_points(near, region, st, opt))
    except TooManyOutliersError:
        raise first from None


def _gradient_window(img: np.ndarray, region: BodyRegion, st, mask: np.ndarray | None,
                     near_mask: bool = False, outline: bool = False) -> _GradientWindow:
    """Steps 3-4: the ROI padded for the box filter, pre-smoothed, differentiated (Eq. 18-22), and its
    ``N`` strongest gradient pixels; the gradient near an invalid pixel is zeroed, and outside the band about the
    lit region's outline for a variegated body's region or with ``outline`` (:func:`_outline_retry`).  ``near_mask``
    (:func:`_masked_retry`): the invalid pixels hold their nearest valid pixel's value, only their own gradient is
    zeroed, and the box filter is not given the mask."""
    r0, r1, c0, c1 = region.roi
    pad = st.box_size // 2 + 6
    r0, c0 = max(0, r0 - pad), max(0, c0 - pad)
    r1, c1 = min(img.shape[0], r1 + pad), min(img.shape[1], c1 + pad)
    near_mask = near_mask and mask is not None
    sub = img[r0:r1, c0:c1].astype(np.float32)  # exact for integer data up to 2^24
    if near_mask:
        sub = nearest_fill(sub, np.asarray(mask, bool)[r0:r1, c0:c1])
    contrast = max(region.peak - region.background, 1e-300)
    sigma_pre = 1.0 if region.noise_sigma > PRESMOOTH_NOISE_FRAC * contrast else 0.0
    if sigma_pre > 0:
        sub_s = cv2.GaussianBlur(sub, (0, 0), sigma_pre, borderType=cv2.BORDER_REPLICATE)
    else:
        sub_s = sub
    g, gr, gc = richardson_gradient(sub_s, dtype=np.float32)
    vsub = None
    if mask is not None:
        vsub = np.asarray(mask, bool)[r0:r1, c0:c1]
        g = np.where(vsub if near_mask else valid_zone(vsub, 4 + int(math.ceil(3 * sigma_pre))), g, 0)
    if region.dark_surface or outline:
        g = np.where(outline_band(region, (r0, r1, c0, c1)), g, 0)
    n_req = int(min(st.n_points, max(10, g.size // 4)))
    return _GradientWindow((r0, r1, c0, c1), sub_s, g, gr, gc, strongest_pixels(g, n_req),
                           None if near_mask else vsub, sigma_pre, near_mask, outline)


def _masked_limb_note(win: _GradientWindow, region: BodyRegion) -> str:
    """Why Check 2 failed when the lit body reaches the band next to the invalid pixels (NaN / fill) that no
    front end uses (``reach`` px, :func:`valid_zone`): the limb lies there (e.g. a solar product whose off-disc
    pixels are blanked 1-2 px outside the limb); else ``""``."""
    if win.valid is None or win.valid.all():
        return ""
    reach = 4 + int(math.ceil(3 * win.presmooth_sigma))
    band = win.valid & ~valid_zone(win.valid, reach)
    n = int(np.count_nonzero(band & (win.smoothed > region.background + 0.25 * (region.peak - region.background))))
    if n < 20:
        return ""
    return (f"; the lit body reaches within {reach} px of the invalid (NaN or fill) pixels on {n} pixels: the limb "
            "lies too close to the mask for the front end (a product with its off-body pixels blanked: use the "
            "frame as taken)")


def _box_filtered_points(win: _GradientWindow, region: BodyRegion, st, opt: GradientOptions) -> tuple[np.ndarray, int]:
    """Step 5 and Check 2: the candidates the box filter (§4.2) keeps, at sub-pixel positions (ROI frame)."""
    cand = win.candidates
    keep, diag = box_filter(win.g, win.smoothed, cand, st.box_size, background=region.background, valid=win.valid)
    if region.bright_sky and keep.any():
        keep &= _outward_bright_to_dark(cand, diag, region, win.offset_rc)
    n_box = int(keep.sum())
    if n_box < opt.min_points_box:
        raise TooManyOutliersError(
            f"Check 2: the box-based filter kept {n_box} of {cand.shape[0]} candidate pixels, fewer than "
            f"min_points_box = {opt.min_points_box}{_masked_limb_note(win, region)}"
        )
    pts_i = cand[keep]
    pts = subpixel_refine(win.g, win.gr, win.gc, pts_i)
    return pts, n_box


def _ransac_taubin(pts: np.ndarray, n_box: int, offset_rc, pri: Prior, st, band, hints: Hints | None,
                   camera: Camera | None, opt: GradientOptions):
    """Steps 6-7 and Check 3: RANSAC (§4.3) in the prior's radius band, a 3-MAD trim and Taubin's fit
    (Eq. 26-35), then the lit side only when the Sun direction is known.  Returns the inlier mask, the
    circle, the RANSAC result and the number of dark-side points dropped."""
    ropt = RansacOptions(
        threshold=st.ransac_dmax,
        max_tests=ransac_tests(n_box, opt.prior),
        min_inliers=MIN_INLIERS,
        min_inlier_fraction=MIN_INLIER_FRACTION,
        radius_range=(band[0], band[1] if math.isfinite(band[1]) else 1e12),
    )
    res = ransac_circle(pts, ropt)
    if not res:
        # Check 3 distinguishes "no circle at all" (too many outliers) from "a circle,
        # but not of the expected radius" (radius inconsistent with the prior)
        free = ransac_circle(pts, replace(ropt, radius_range=None))
        if free and free.circle is not None:
            check_radius(free.circle.radius, pri, band)
        raise TooManyOutliersError(f"Check 3: RANSAC found no consistent circle: {res.reason}")
    inl = res.inliers.copy()
    fit = res.circle
    assert fit is not None
    # final robust trim
    rr = circle_residuals(pts, fit.center_rc, fit.radius)
    mad = 1.4826 * float(np.median(np.abs(rr[inl] - np.median(rr[inl]))))
    tol = max(TRIM_MIN_PX, 3.0 * mad)
    inl2 = inl & (np.abs(rr) <= tol)
    if inl2.sum() >= MIN_INLIERS:
        inl = inl2
        fit = fit_circle_taubin(pts[inl])
    n_dark = 0
    if hints is not None and hints.sun_dir_camera is not None and pri.phase_rad is not None:
        inl, fit, n_dark = _lit_side_only(pts, inl, fit, offset_rc, hints, camera, pri.phase_rad,
                                          MIN_INLIERS, band)
    return inl, fit, res, n_dark

__all__ = ["GradientOptions", "gradient_front_end"]
