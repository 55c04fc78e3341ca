"""The scan-line front end (the illuminated-ellipsoid paper §IV-A, §VI; :mod:`jaxlimb.imaging.scanline` has the
method): threshold, largest region and its inertia axis, scan lines, the lit set of transitions chosen (the Sun's side,
else the harder edge, else the circle nearer the prior) and checked (a hard edge, not a terminator's ramp)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..conics.taubin import CircleFit
from ..errors import TooManyOutliersError, TooThinError
from ..geometry.camera import Camera
from .candidates import LimbCandidates, lit_arc
from .crop import BodyRegion, DARK_SURFACE_FRAC, detect_body, DetectOptions, nearest_fill
from .front_end_common import check_radius, radius_band, resolve_prior, valid_zone
from .io import validate_image
from .prior import Hints, Prior, PriorOptions, sun_direction_image
from .scanline import (inertia_axes, InertiaAxes, largest_filled, MASK_REACH_PX, masked_binary, ramp_ratio,
                       scan_transitions, threshold_eq10, trimmed_fit)


#: Scan-line spacing as a fraction of the radius estimate (paper: 1/11) ...
SPACING_FRAC = 1.0 / 11.0


#: ... lines at offsets ``k * spacing`` for ``|k| <= N_LINES_HALF`` (21 lines).
N_LINES_HALF = 10


#: Median filter size before the threshold (the paper's "simple median filter").
MEDIAN_KSIZE = 3


#: Smallest accepted mask correlation of a transition (the maximum is 4).
MIN_CORRELATION = 3


#: Fewest transitions in the lit set, else :class:`~jaxlimb.errors.TooManyOutliersError`.
MIN_POINTS = 6


#: Smallest admissible ``lambda_min / lambda_max`` of the lit region (illumination range), else
#: :class:`~jaxlimb.errors.TooThinError`.
MIN_EIGEN_RATIO = 0.005


#: Both sets are merged when their circles agree within this (px; centre and radius): a fully lit disc.
MERGE_TOLERANCE_PX = 2.0


#: Without a Sun direction, a set whose median edge step is this many times the other's is the lit limb (the limb
#: is a hard edge, the terminator a ramp).
HARD_EDGE_RATIO = 2.0


#: The chosen set's median edge step must reach this fraction of the ROI's 99.5th-percentile gradient ...
MIN_EDGE_FRACTION = 0.25


#: ... and this fraction of the body's contrast per pixel (a limb blurred by a PSF of sigma px steps by ~0.4/sigma
#: of its brightness per pixel, a terminator ramp by ~1/R), else the lit limb is deemed not visible.
MIN_EDGE_CONTRAST = 0.04


#: One set, no Sun direction: largest ratio of the brightness 6-12 px inside the edge to that 3 px inside (above the
#: sky): ~1 for a limb (1.2 for the Sun's limb darkening), 2-4 for a terminator ramp.
MAX_RAMP_RATIO = 1.8


@dataclass(frozen=True)
class ScanlineOptions:
    """Settings of :func:`scanline_front_end`: ``detect``, the region detection's
    (:class:`~jaxlimb.imaging.crop.DetectOptions`); ``prior``, the §3 prior's
    (:class:`~jaxlimb.imaging.prior.PriorOptions`).  The scan lines' own numbers are the module's constants."""

    detect: DetectOptions = field(default_factory=DetectOptions)
    prior: PriorOptions = field(default_factory=PriorOptions)


def scanline_front_end(
    image: np.ndarray,
    prior: Prior | None = None,
    *,
    hints: Hints | None = None,
    camera: Camera | None = None,
    options: ScanlineOptions | None = None,
    mask: np.ndarray | None = None,
) -> LimbCandidates:
    """Limb points and initial circle by threshold + inertia axis + scan lines (§IV-A, §VI).

    Parameters and raised errors as :func:`jaxlimb.imaging.gradient.gradient_front_end`.  ``mask``
    (``True`` = measured pixel, :mod:`jaxlimb.imaging.formats`): masked pixels are neither limb nor
    background -- the threshold uses the valid pixels only, a masked pixel takes the thresholded value
    of its nearest valid pixel (so a missing band does not cut the lit region in two), and a transition
    whose window or grey profile (:data:`MASK_REACH_PX`) reaches a masked pixel is dropped;
    additionally :class:`~jaxlimb.errors.TooThinError` when the eigenvalue ratio is
    below :data:`MIN_EIGEN_RATIO` and :class:`~jaxlimb.errors.TooManyOutliersError`
    when fewer than :data:`MIN_POINTS` lines cross the lit limb.

    Returns
    -------
    LimbCandidates
        ``front_end="scanline"``; ``info["other_set"]`` holds the rejected set's
        points and circle (``info["choice"]`` says why).
    """
    opt = options or ScanlineOptions()
    t0 = time.perf_counter()
    img = validate_image(image, reject_constant=False, as_float64=False)
    region = detect_body(nearest_fill(img, mask), opt.detect)
    pri = resolve_prior(img, region, prior, hints, camera, opt.prior)
    band = radius_band(pri, region)
    lr = _lit_region(img, region, mask)
    r0, _, c0, _ = region.roi
    sun_rc = _sun_image_direction(hints, camera, pri, (lr.axes.centroid_rc[0] + r0, lr.axes.centroid_rc[1] + c0))
    axis = np.array(sun_rc) if sun_rc is not None else np.array(lr.axes.axis_rc)
    spacing = SPACING_FRAC * pri.expected_radius_px
    offsets = spacing * np.arange(-N_LINES_HALF, N_LINES_HALF + 1, dtype=float)
    tr = scan_transitions(
        lr.binary,
        lr.sub,
        lr.axes.centroid_rc,
        axis,
        offsets,
        min_correlation=MIN_CORRELATION,
                valid_shape=img.shape,
        valid_offset=(r0, c0),
        valid_mask=None if lr.valid is None else valid_zone(lr.valid, MASK_REACH_PX),
    )
    sel = _select_lit_set(tr, lr, region, pri, axis, sun_rc is not None)
    check_radius(sel.fit.radius, pri, band)

    info = _scan_info(pri, region, lr, sel, axis, spacing, offsets.size, np.array([r0, c0], float))
    info["timings_s"] = {"total": time.perf_counter() - t0}
    return _limb_candidates(sel, (r0, c0), sun_rc, info)


def _limb_candidates(sel: _LitSet, offset_rc, sun_rc, info: dict) -> LimbCandidates:  # noqa: ANN001
    """The front end's answer from the lit set ``sel`` (ROI frame): the lit arc about the Sun's image direction, or
    all round for a merged (fully lit) set with the Sun unknown."""
    points_full = sel.points + np.asarray(offset_rc, float)
    center = (sel.fit.center_rc[0] + offset_rc[0], sel.fit.center_rc[1] + offset_rc[1])
    if sel.merged and sun_rc is None:
        lit_dir, half = lit_arc(points_full, center)
    else:
        lit_dir, half = lit_arc(points_full, center, sun_rc)
    return LimbCandidates(points_rc=points_full, center_rc=(float(center[0]), float(center[1])),
                          radius=float(sel.fit.radius), residual_rms=float(sel.fit.rms), lit_direction=lit_dir,
                          lit_halfangle=half, front_end="scanline", info=info)


@dataclass(frozen=True)
class _LitRegion:
    """The thresholded lit region of the ROI (§IV-A): raw and median-filtered pixels, the validity of
    each, the threshold, the binary region and its inertia axes."""

    sub: np.ndarray
    filtered: np.ndarray
    valid: np.ndarray | None
    threshold: float
    binary: np.ndarray
    axes: InertiaAxes
    dark_surface: bool = False


def _lit_region(img: np.ndarray, region: BodyRegion, mask: np.ndarray | None) -> _LitRegion:
    """Threshold, largest filled region and its inertia axes; :class:`TooThinError` below :data:`MIN_EIGEN_RATIO`."""
    r0, r1, c0, c1 = region.roi
    sub = img[r0:r1, c0:c1].astype(np.float32)  # exact for integer data up to 2^24
    sub_f = cv2.medianBlur(sub, MEDIAN_KSIZE) if MEDIAN_KSIZE > 1 else sub
    vsub = None if mask is None else np.asarray(mask, bool)[r0:r1, c0:c1]
    gt, low = _binary_threshold(sub_f, vsub, region.noise_sigma)
    dark = region.dark_surface and low < gt  # a variegated body (crop.dark_surface_region): its low threshold
    gt = low if dark else gt
    binary = largest_filled(masked_binary(sub_f > gt, vsub))
    ax = inertia_axes(binary)
    if ax.eigen_ratio < MIN_EIGEN_RATIO:
        raise TooThinError(
            f"eigenvalue ratio lambda_min/lambda_max = {ax.eigen_ratio:.3g} of the lit region is below "
            f"{MIN_EIGEN_RATIO:g} (too thin to process)"
        )
    return _LitRegion(sub, sub_f, vsub, gt, binary, ax, dark)


@dataclass(frozen=True)
class _LitSet:
    """The scan-line transitions taken as the lit limb (merged with the other set where consistent)."""

    points: np.ndarray
    fit: CircleFit
    merged: bool
    other_set: tuple
    info: dict


def _select_lit_set(tr, lr: _LitRegion, region: BodyRegion, pri: Prior, axis: np.ndarray, sun_known: bool) -> _LitSet:
    """Entry or exit transitions as the lit limb (§VI): trimmed circle fits of both sets, the choice, the
    ramp and hard-edge checks, and the merge of a consistent other set."""
    entry, exit_ = tr.entry, tr.exit
    f_in, k_in = trimmed_fit(entry, MIN_POINTS)
    f_out, k_out = trimmed_fit(exit_, MIN_POINTS)
    sets = {"entry": (entry, f_in, k_in), "exit": (exit_, f_out, k_out)}
    st_in = float(np.nanmedian(tr.entry_strength[k_in])) if f_in is not None else 0.0
    st_out = float(np.nanmedian(tr.exit_strength[k_out])) if f_out is not None else 0.0
    g_ref, contrast = _edge_references(lr, region)
    lit, other, choice_reason = _choose_lit_set(f_in, f_out, st_in, st_out, sun_known, pri)
    pts, fit, keep = sets[lit]
    if fit is None:
        raise TooManyOutliersError(
            f"scan lines found {pts.shape[0]} lit-limb transitions, fewer than {MIN_POINTS} "
            f"usable for a circle fit (is the lit limb outside the frame?)"
        )
    ramp = math.nan
    if not sun_known and sets[other][1] is None:
        bright = axis / np.linalg.norm(axis) * (1.0 if lit == "entry" else -1.0)
        ramp = _check_not_a_ramp(lr.sub, pts[keep], bright, pri.expected_radius_px)
    _check_hard_edge(st_out if lit == "exit" else st_in, g_ref, contrast)
    pts, fit, merged = _merge_sets(pts[keep], fit, sets[other])
    info = {"lit_set": lit, "edge_step_entry": st_in, "edge_step_exit": st_out, "edge_step_reference": g_ref,
            "ramp_ratio": ramp, "merged": merged, "choice": choice_reason}
    return _LitSet(pts, fit, merged, sets[other], info)


def _check_not_a_ramp(sub: np.ndarray, pts: np.ndarray, bright: np.ndarray, R_est: float) -> float:
    """A single set and no Sun direction: a limb is a step (flat on its bright side), a terminator a ramp
    (brightness keeps rising into the body).  Returns the far/near brightness ratio.

    Raises
    ------
    TooManyOutliersError
        The ratio exceeds :data:`MAX_RAMP_RATIO`.
    """
    ramp = ramp_ratio(sub, pts, bright, far=max(6.0, min(12.0, 0.15 * R_est)))
    if not ramp <= MAX_RAMP_RATIO:
        raise TooManyOutliersError(
            f"only one set of scan-line transitions was found and its profile is a ramp, not a limb "
            f"(brightness ratio far/near inside = {ramp:.3g} > {MAX_RAMP_RATIO:g}): "
            f"the lit limb is not visible (outside the frame?)"
        )
    return ramp


def _edge_references(lr: _LitRegion, region: BodyRegion) -> tuple[float, float]:
    """The hard-edge references: the 99.5th percentile of the grey-level gradient (DN/px) and the body's contrast.

    Over the ROI and from the brightest pixel, unless the region is a variegated body's
    (:func:`~.crop.dark_surface_region`): then both are taken in a band about the region's outline (limb and
    terminator; the contrast: the median level just inside it), for the strongest edges and the brightest
    pixels (the Earth's clouds on a dark ocean) lie inside the body, and its Lambert limb at low phase, a
    soft edge beside them, was refused as "not a hard edge" (``tests/imaging/test_variegated.py``)."""
    step = max(1, int(math.sqrt(lr.filtered.size / 250_000)))  # subsample large ROIs (speed)
    f = lr.filtered[::step, ::step]
    gy, gx = np.gradient(f)
    g = np.hypot(gy, gx)
    contrast = float(region.peak - region.background)
    if not lr.dark_surface:
        return float(np.percentile(g, 99.5)) / step, contrast
    b = np.ascontiguousarray(lr.binary[::step, ::step], dtype=np.uint8)
    k = np.ones((3, 3), np.uint8)
    inner = cv2.erode(b, k, iterations=3) > 0
    band = (cv2.dilate(b, k, iterations=3) > 0) & ~inner
    if np.count_nonzero(band) < 50:
        return float(np.percentile(g, 99.5)) / step, contrast
    rim = (b > 0) & ~inner
    return float(np.percentile(g[band], 99.5)) / step, min(contrast, float(np.median(f[rim])) - float(region.background))


def _check_hard_edge(st_lit: float, g_ref: float, contrast: float) -> None:
    """The chosen transitions must be a hard edge: median step >= max(:data:`MIN_EDGE_FRACTION` x the
    99.5th-percentile gradient, :data:`MIN_EDGE_CONTRAST` x the body's contrast) (TooManyOutliersError)."""
    need = max(MIN_EDGE_FRACTION * g_ref, MIN_EDGE_CONTRAST * contrast)
    if not st_lit >= need:
        raise TooManyOutliersError(
            f"the chosen scan-line transitions are not a hard edge: median step {st_lit:.4g} DN/px is below "
            f"{need:.4g} DN/px = max({MIN_EDGE_FRACTION:g} x the 99.5th-percentile "
            f"gradient {g_ref:.4g}, {MIN_EDGE_CONTRAST:g} x the contrast {contrast:.4g}); "
            f"the lit limb is not visible (outside the frame?)"
        )


def _binary_threshold(sub_f: np.ndarray, valid: np.ndarray | None, noise_sigma: float) -> tuple[float, float]:
    """Threshold of the lit region: Eq. (10) on the valid pixels, floored at 6 sigma above the sky as in
    :func:`detect_body` (the 3x3 median leaves ~1/2 of the per-pixel noise); and the low threshold of a
    variegated body, ``sky + max(6 sigma, dark_surface_frac x range)`` (:func:`~.crop.dark_surface_region`)."""
    if valid is None or not valid.any():
        vals = sub_f
        sky = float(np.percentile(sub_f[:: max(1, sub_f.shape[0] // 200), :: max(1, sub_f.shape[1] // 200)], 2.0))
    else:
        vals = sub_f[valid]
        sky = float(np.percentile(vals[:: max(1, vals.size // 40_000)], 2.0))
    floor = sky + 6.0 * (0.5 if MEDIAN_KSIZE > 1 else 1.0) * noise_sigma
    low = max(floor, sky + DARK_SURFACE_FRAC * (float(vals.max()) - sky))
    return max(threshold_eq10(vals), floor), low


def _scan_info(pri: Prior, region: BodyRegion, lr: _LitRegion, sel: _LitSet, axis: np.ndarray, spacing: float,
               n_lines: int, off: np.ndarray) -> dict:
    """The scan-line front end's settings, counts and the rejected set (:attr:`LimbCandidates.info`)."""
    o_pts, o_fit, _ = sel.other_set
    r0, c0 = int(off[0]), int(off[1])
    return {
        "prior": pri,
        "roi": region.roi,
        "region": region,
        "threshold": lr.threshold,
        "centroid_rc": (lr.axes.centroid_rc[0] + r0, lr.axes.centroid_rc[1] + c0),
        "axis_rc": tuple(float(x) for x in axis / np.linalg.norm(axis)),
        "eigen_ratio": lr.axes.eigen_ratio,
        "line_spacing_px": spacing,
        "n_lines": int(n_lines),
        **sel.info,
        "other_set": {
            "points_rc": o_pts + off,
            "center_rc": None if o_fit is None else (o_fit.center_rc[0] + r0, o_fit.center_rc[1] + c0),
            "radius": None if o_fit is None else o_fit.radius,
            "residual_rms": None if o_fit is None else o_fit.rms,
        },
        "residual_max": sel.fit.max_abs,
        "cropped": region.crop,
    }


def _sun_image_direction(hints: Hints | None, camera: Camera | None, pri: Prior, centroid_rc) -> tuple | None:
    """The Sun's direction in the image (from the hints' camera-frame vector, else the prior's), or None."""
    if hints is not None and hints.sun_dir_camera is not None:
        return sun_direction_image(hints.sun_dir_camera, camera, centroid_rc if camera is not None else None)
    return pri.sun_dir_rc


def _choose_lit_set(f_in: CircleFit | None, f_out: CircleFit | None, st_in: float, st_out: float, sun_known: bool,
                    pri: Prior) -> tuple[str, str, str]:
    """Which set of transitions (``entry``/``exit`` of the lit region) is the lit limb: the Sun's side when
    known, else the clearly harder edge, else the circle closer to the expected radius with the smaller
    residual.  Returns ``(lit, other, reason)``."""
    if sun_known:
        return "exit", "entry", "Sun direction from hints: the lit limb is where the lines leave the lit region"
    if f_in is not None and f_out is not None and max(st_in, st_out) >= HARD_EDGE_RATIO * min(st_in, st_out):
        lit, other = ("exit", "entry") if st_out >= st_in else ("entry", "exit")
        return lit, other, f"hard edge: median step entry {st_in:.4g}, exit {st_out:.4g} DN/px"
    R_est, u = pri.expected_radius_px, max(pri.radius_uncertainty_frac, 1e-3)

    def score(f: CircleFit | None) -> float:
        if f is None:
            return math.inf
        dr = (f.radius - R_est) / (u * R_est)
        return (f.rms + 1e-3) * (1.0 + dr * dr)

    s_in, s_out = score(f_in), score(f_out)
    lit, other = ("exit", "entry") if s_out <= s_in else ("entry", "exit")
    return lit, other, f"score rms*(1+(dR/(u p_r))^2): entry {s_in:.4g}, exit {s_out:.4g}"


def _merge_sets(pts: np.ndarray, fit: CircleFit, other) -> tuple[np.ndarray, CircleFit, bool]:
    """Both sets in one trimmed fit when the other set's circle agrees within :data:`MERGE_TOLERANCE_PX`
    (a fully lit disc: entry and exit are both limb).  Returns ``(points, fit, merged)``."""
    o_pts, o_fit, o_keep = other
    if (
        o_fit is not None
        and abs(o_fit.radius - fit.radius) <= MERGE_TOLERANCE_PX
        and math.hypot(o_fit.center_rc[0] - fit.center_rc[0], o_fit.center_rc[1] - fit.center_rc[1]) <= MERGE_TOLERANCE_PX
    ):
        both = np.concatenate([pts, o_pts[o_keep]])
        f2, k2 = trimmed_fit(both, MIN_POINTS)
        if f2 is not None:
            return both[k2], f2, True
    return pts, fit, False


__all__ = ["HARD_EDGE_RATIO", "MAX_RAMP_RATIO", "MEDIAN_KSIZE", "MERGE_TOLERANCE_PX", "MIN_CORRELATION", "MIN_EDGE_CONTRAST", "MIN_EDGE_FRACTION", "MIN_EIGEN_RATIO", "MIN_POINTS", "N_LINES_HALF", "SPACING_FRAC", "ScanlineOptions", "scanline_front_end"]
