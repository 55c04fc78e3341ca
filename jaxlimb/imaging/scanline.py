r"""Scan-line front end: §IV-A and §VI of Mortari, D'Souza & Zanetti, *Image
Processing of Illuminated Ellipsoid* (JSR 2016).

Pipeline (:func:`scanline_front_end`):

1. validate; :func:`~jaxlimb.imaging.crop.detect_body` (no-body test, ROI,
   image Checks 1-2); the prior (hints + camera, or measured on the image);
2. 3x3 median filter of the ROI (§VI: removes stars, hot and dead pixels);
3. binary image by the threshold of Eq. (10),
   :math:`G_t = G_{min} + (G_{max} - G_{min})/4` (floored at 6 sigma above the sky,
   as in :func:`~jaxlimb.imaging.crop.detect_body`); the largest 8-connected
   component, holes filled (decision: stars and dark maria would otherwise
   create spurious transitions);
4. centroid and inertia tensor of the binary region, Eq. (11); the axis of
   symmetry and the eigenvalue ratio :math:`\lambda_{min}/\lambda_{max}`;
5. lines parallel to the axis of symmetry, spaced :math:`\hat R/11` (§VI), through
   offsets :math:`k \hat R/11`, :math:`|k| \le 10`, from the centroid;
6. along each line, the correlation with the 8-pixel mask
   ``[0, 0, 0, 0, 1, 1, 1, 1]`` in both directions gives two transition sets
   (entering and leaving the lit region);
7. Taubin's fit (Eq. 26-35 of the Aerospace 2015 paper) of each set; the lit
   limb is chosen (see below) and returned as :class:`LimbCandidates`.

Decisions and corrections:

* **Eq. (11) as printed is inconsistent**: its diagonal holds
  :math:`\sum (r_i - r_b)^2` and :math:`\sum (c_i - c_b)^2` (a covariance) while
  its off-diagonal has the minus sign of an inertia tensor.  The eigenvalues are
  the same either way, but the eigenvectors of the printed matrix are the
  covariance's reflected about the row axis, so its :math:`\lambda_{max}`
  eigenvector is *not* the axis of symmetry in general.  The axis of symmetry
  of a lit crescent/gibbous region (the line through the body centre toward
  the Sun) is its direction of least spread, i.e. the eigenvector of the
  **largest moment of inertia** of the proper inertia tensor
  :math:`T = \operatorname{tr}(S) I - S` (S the covariance).  We use that.
* The paper's mask is not zero-mean, so a plain correlation with it is also
  maximal inside the body; we correlate the binary profile with
  ``2 * mask - 1`` (= ``[-1,-1,-1,-1,1,1,1,1]``), which peaks (value 4) exactly at a
  dark-to-bright transition.  Transitions with a correlation below
  ``min_correlation`` (3) are discarded, as are those whose mask window leaves
  the frame (no limb points on the image border).
* Sub-pixel position: the binary transition is refined on the grey profile
  (bilinear samples along the line) to the crossing of the mid-level between
  the dark level outside and the bright level inside (16-sample window);
  this removes the +-0.5 px quantisation and the outward bias of the 25 %
  threshold of Eq. (10).
* Choice of the lit limb (the paper: "minimum standard deviation of residuals"):
  when the Sun direction is known (hints) the lines are oriented toward the
  Sun and the lit limb is the set where the lines *leave* the lit region.
  Otherwise (decision) the limb is recognised first as the **hard edge**: the
  median grey-level step (DN/px) at its transitions is at least
  ``hard_edge_ratio`` (2) times the terminator's, whose Lommel-Seeliger /
  Lambert brightness ramps up over many pixels; if the steps are comparable
  the set with the smaller score ``rms * (1 + (dR / (u p_r))^2)`` is taken
  (``dR`` the distance of its radius from the prior radius :math:`p_r`, ``u``
  the prior's relative uncertainty: smaller residuals *and* a radius closer to
  the expected one).  The residual criterion alone fails when the lit limb is
  cut by the frame (only the terminator set survives) or at low phase with
  texture.  The chosen set must be a hard edge (``min_edge_fraction``) or a
  :class:`~jaxlimb.errors.TooManyOutliersError` is raised -- a terminator is
  never returned as the limb.  When only one set exists (the other side cut by
  the frame) and no Sun direction is known, the set must also look like a limb
  on its bright side (``max_ramp_ratio``).  When both sets agree (full disk) they
  are merged.
* Each set is trimmed once at ``max(1 px, 3 x 1.4826 MAD)`` of its residuals before
  the final fit (a crater or a horn can spoil a single line).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..conics.taubin import CircleFit, DegenerateFitError, circle_residuals, fit_circle_taubin
from ..errors import ConfigError, TooManyOutliersError, TooThinError
from ..geometry.camera import Camera
from .candidates import LimbCandidates, lit_arc
from .crop import BodyRegion, DetectOptions, detect_body, nearest_fill
from .gradient import _bilinear, check_radius, radius_band, resolve_prior, valid_zone
from .io import validate_image
from .prior import Hints, Prior, PriorOptions, sun_direction_image

#: The 8-pixel mask of §VI.
SCAN_MASK = (0, 0, 0, 0, 1, 1, 1, 1)


@dataclass(frozen=True)
class ScanlineOptions:
    """Settings of :func:`scanline_front_end`.

    Attributes
    ----------
    spacing_frac
        Line spacing as a fraction of the radius estimate (paper: 1/11).
    n_lines_half
        Lines at offsets ``k * spacing`` for ``|k| <= n_lines_half`` (10 -> 21 lines).
    median_ksize
        Median filter size (odd, 1 = none; paper: a "simple median filter").
    min_correlation
        Smallest accepted mask correlation (the maximum is 4).
    min_points
        Fewest transitions in the lit set (>= 3), else :class:`TooManyOutliersError`.
    min_eigen_ratio
        Smallest admissible ``lambda_min / lambda_max`` (illumination range), else
        :class:`TooThinError`.
    subpixel
        Refine transitions on the grey profile.
    merge_tolerance_px
        Both sets are merged when their circles agree within this (centre and radius).
    hard_edge_ratio
        Without a Sun direction, a set whose median edge step (DN/px) is this many
        times the other's is the lit limb (the limb is a hard edge, the terminator a ramp).
    min_edge_fraction
        The chosen set's median edge step must reach this fraction of the ROI's
        99.5th-percentile gradient, else the lit limb is deemed not visible
        (:class:`~jaxlimb.errors.TooManyOutliersError`); never return a terminator.
    min_edge_contrast
        ... and this fraction of the body's contrast (peak - sky) per pixel: a limb
        blurred by a PSF of sigma px steps by ~0.4/sigma of its brightness per
        pixel, a terminator ramp by ~1/R.
    max_ramp_ratio
        When only one transition set exists and no Sun direction is known: largest
        accepted ratio of the brightness 6-12 px inside the edge to that 3 px inside
        (above the sky): ~1 for a limb (Lommel-Seeliger is flat up to the limb;
        1.2 for the Sun's limb darkening), 2-4 for a terminator ramp.
    detect, prior
        :class:`~jaxlimb.imaging.crop.DetectOptions`, :class:`~jaxlimb.imaging.prior.PriorOptions`.
    """

    spacing_frac: float = 1.0 / 11.0
    n_lines_half: int = 10
    median_ksize: int = 3
    min_correlation: int = 3
    min_points: int = 6
    min_eigen_ratio: float = 0.005
    subpixel: bool = True
    merge_tolerance_px: float = 2.0
    hard_edge_ratio: float = 2.0
    min_edge_fraction: float = 0.25
    min_edge_contrast: float = 0.04
    max_ramp_ratio: float = 1.8
    detect: DetectOptions = field(default_factory=DetectOptions)
    prior: PriorOptions = field(default_factory=PriorOptions)

    def __post_init__(self) -> None:
        if not (0 < self.spacing_frac <= 1):
            raise ConfigError(f"ScanlineOptions.spacing_frac must be in (0, 1], got {self.spacing_frac!r}")
        if self.n_lines_half < 1:
            raise ConfigError(f"ScanlineOptions.n_lines_half must be >= 1, got {self.n_lines_half!r}")
        if self.median_ksize < 1 or self.median_ksize % 2 == 0 or self.median_ksize > 5:
            raise ConfigError(f"ScanlineOptions.median_ksize must be 1, 3 or 5, got {self.median_ksize!r}")
        if not 1 <= self.min_correlation <= 4:
            raise ConfigError(f"ScanlineOptions.min_correlation must be in [1, 4], got {self.min_correlation!r}")
        if self.min_points < 3:
            raise ConfigError(f"ScanlineOptions.min_points must be >= 3, got {self.min_points!r}")


@dataclass(frozen=True)
class InertiaAxes:
    """Eq. (11) results for a binary region.

    Attributes
    ----------
    centroid_rc
        :math:`(r_b, c_b)`.
    axis_rc
        Unit axis of symmetry (largest moment of inertia = least spread).
    eigen_ratio
        :math:`\\lambda_{min}/\\lambda_{max}` (1 = disk, 0 = line).
    spread_major
        Standard deviation of the region along the axis perpendicular to ``axis_rc``.
    """

    centroid_rc: tuple[float, float]
    axis_rc: tuple[float, float]
    eigen_ratio: float
    spread_major: float


def inertia_axes(binary: np.ndarray) -> InertiaAxes:
    """Centroid and principal axes of a binary image (Eq. 11, see the correction in the module docstring)."""
    m = cv2.moments(np.ascontiguousarray(binary, dtype=np.uint8), binaryImage=True)
    if m["m00"] <= 0:
        raise TooThinError("the thresholded image has no lit pixel")
    # OpenCV moments: x = col, y = row; mu are central moments
    rb, cb = m["m01"] / m["m00"], m["m10"] / m["m00"]
    S = np.array([[m["mu02"], m["mu11"]], [m["mu11"], m["mu20"]]]) / m["m00"]
    T = np.trace(S) * np.eye(2) - S  # proper inertia tensor (per unit mass)
    w, V = np.linalg.eigh(T)
    axis = V[:, 1]  # largest moment of inertia
    ratio = float(w[0] / w[1]) if w[1] > 0 else 1.0
    return InertiaAxes((float(rb), float(cb)), (float(axis[0]), float(axis[1])), ratio, float(math.sqrt(max(w[1], 0))))


def threshold_eq10(a: np.ndarray) -> float:
    """Eq. (10): :math:`G_t = G_{min} + (G_{max} - G_{min})/4`."""
    lo, hi = float(a.min()), float(a.max())
    return lo + 0.25 * (hi - lo)


def _largest_filled(binary: np.ndarray) -> np.ndarray:
    """The largest outer contour (8-connected) of a binary image, filled (holes removed)."""
    b = np.ascontiguousarray(binary, dtype=np.uint8)
    cnts, _ = cv2.findContours(b, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    out = np.zeros_like(b)
    if not cnts:
        return out
    k = int(np.argmax([cv2.contourArea(c) + len(c) for c in cnts]))
    cv2.drawContours(out, cnts, k, 1, thickness=cv2.FILLED)
    return out


def _line_profiles(B: np.ndarray, base: np.ndarray, a: np.ndarray, t: np.ndarray, valid_shape, valid_offset, valid_mask):  # type: ignore[no-untyped-def]
    """The binary image sampled (nearest pixel) along the lines ``base + t a``, and where each sample is usable."""
    R, C = B.shape
    ir = np.rint(base[:, None, 0] + t[None, :] * a[0]).astype(np.int64)
    ic = np.rint(base[:, None, 1] + t[None, :] * a[1]).astype(np.int64)
    inside = (ir >= 0) & (ir < R) & (ic >= 0) & (ic < C)
    if valid_shape is not None:  # inside the full frame (ROI coordinates shifted by valid_offset)
        fr, fc = ir + valid_offset[0], ic + valid_offset[1]
        valid = (fr >= 1) & (fr < valid_shape[0] - 1) & (fc >= 1) & (fc < valid_shape[1] - 1)
    else:
        valid = inside
    if valid_mask is not None:
        vm = np.asarray(valid_mask, bool)
        valid = valid & inside & vm[np.clip(ir, 0, R - 1), np.clip(ic, 0, C - 1)]
    prof = np.zeros(ir.shape)
    prof[inside] = B[ir[inside], ic[inside]]
    return prof, valid


def _mask_correlation_peaks(prof: np.ndarray, valid: np.ndarray, min_correlation: int):  # type: ignore[no-untyped-def]
    """Per line, the first window maximising the entry mask correlation and the last maximising the exit one (§VI).

    Returns ``(lines, t_window_centre)`` index arrays for entries and for exits; a line whose best
    correlation is below ``min_correlation`` has no transition of that kind.
    """
    m = 2.0 * np.asarray(SCAN_MASK, float) - 1.0  # [-1]*4 + [1]*4
    K = m.size
    nwin = prof.shape[1] - K + 1
    win = np.lib.stride_tricks.sliding_window_view(prof, K, axis=1)  # (L, nwin, K)
    vwin = np.lib.stride_tricks.sliding_window_view(valid, K, axis=1).all(-1)
    corr_in = np.where(vwin, win @ m, -np.inf)
    corr_out = np.where(vwin, win @ m[::-1], -np.inf)
    mi, mo = corr_in.max(axis=1), corr_out.max(axis=1)
    j_in = np.argmax(corr_in >= mi[:, None], axis=1)  # first maximal window
    j_out = nwin - 1 - np.argmax(corr_out[:, ::-1] >= mo[:, None], axis=1)  # last maximal window
    li_in, li_out = np.nonzero(mi >= min_correlation)[0], np.nonzero(mo >= min_correlation)[0]
    half = (K - 1) / 2.0
    return (li_in, j_in[li_in] + half), (li_out, j_out[li_out] + half)


def scan_transitions(
    binary: np.ndarray,
    grey: np.ndarray | None,
    origin_rc,
    axis_rc,
    offsets: np.ndarray,
    *,
    min_correlation: int = 3,
    subpixel: bool = True,
    valid_shape: tuple[int, int] | None = None,
    valid_offset: tuple[int, int] = (0, 0),
    valid_mask: np.ndarray | None = None,
):
    """Transitions of a binary image along parallel lines (mask correlation, §VI).

    Lines: ``origin + k n + t a`` for each offset ``k`` (``n`` perpendicular to
    ``a``), ``t`` in unit steps over the whole array.  ``valid_mask`` (shape of ``binary``,
    ``True`` = usable pixel): windows touching an unusable pixel are not transitions.

    Returns
    -------
    Transitions
        ``entry``, ``exit``: ``(m, 2)`` arrays of ``(row, col)`` where each line
        enters / leaves the lit region moving along ``+axis_rc``;
        ``entry_strength``, ``exit_strength``: the steepest grey-level step
        (DN/px) of the profile at each transition (``nan`` without ``grey``).
    """
    a = np.asarray(axis_rc, float)
    a = a / np.linalg.norm(a)
    nvec = np.array([-a[1], a[0]])
    base = np.asarray(origin_rc, float)[None, :] + offsets[:, None] * nvec[None, :]  # (L, 2)
    tmax = math.hypot(*np.shape(binary)) + 8
    t = np.arange(-tmax, tmax + 1.0)
    prof, valid = _line_profiles(np.asarray(binary), base, a, t, valid_shape, valid_offset, valid_mask)
    entries, exits = _mask_correlation_peaks(prof, valid, min_correlation)

    def to_points(li: np.ndarray, tw: np.ndarray, sgn: float):  # type: ignore[no-untyped-def]
        tt = t[0] + tw
        strength = np.full(tt.shape, np.nan)
        if grey is not None and li.size:
            tt2, strength = _refine(grey, base[li], a, tt, np.full(tt.shape, sgn))
            if subpixel:
                tt = tt2
        return np.stack([base[li, 0] + tt * a[0], base[li, 1] + tt * a[1]], axis=1).reshape(-1, 2), strength

    pe, se = to_points(*entries, 1.0)
    px, sx = to_points(*exits, -1.0)
    return Transitions(pe, px, se, sx)


@dataclass(frozen=True)
class Transitions:
    """Output of :func:`scan_transitions` (iterable as ``entry, exit``)."""

    entry: np.ndarray
    exit: np.ndarray
    entry_strength: np.ndarray
    exit_strength: np.ndarray

    def __iter__(self):
        return iter((self.entry, self.exit))


#: Transitions closer than this to a masked pixel are dropped: the grey profile of :func:`_refine`
#: (+-8 px) and the 3x3 median must not see the fill value of a masked pixel.
MASK_REACH_PX = 9


def _masked_binary(binary: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    """The thresholded image with each masked pixel set to its nearest valid pixel's value."""
    if valid is None or valid.all() or not valid.any():
        return binary
    from scipy import ndimage

    idx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return binary[idx[0], idx[1]]


def _refine(grey: np.ndarray, base: np.ndarray, a: np.ndarray, t0: np.ndarray, sgn: np.ndarray, half: int = 8):
    """Mid-level crossing of the grey profile near each transition (sgn=+1: dark->bright along +a).

    Returns the refined line parameters and the steepest step (DN/px) within
    +-2 samples of the crossing.
    """
    k = np.arange(-half, half + 1, dtype=float)
    tt = t0[:, None] + sgn[:, None] * k[None, :]  # oriented dark -> bright
    pr = base[:, 0, None] + tt * a[0]
    pc = base[:, 1, None] + tt * a[1]
    prof = _bilinear(grey, pr, pc)
    lo = prof[:, :half].min(1)
    hi = prof[:, half + 1 :].max(1)
    lev = 0.5 * (lo + hi)
    above = prof >= lev[:, None]
    up = above[:, 1:] & ~above[:, :-1]  # crossing between j and j+1
    dprof = np.diff(prof, axis=1)
    out = t0.copy()
    strength = dprof[:, half - 3 : half + 3].max(1)
    for i in range(prof.shape[0]):
        js = np.nonzero(up[i])[0]
        if js.size == 0 or not hi[i] > lo[i]:
            continue
        j = js[np.argmin(np.abs(js + 0.5 - half))]
        v0, v1 = prof[i, j], prof[i, j + 1]
        frac = (lev[i] - v0) / (v1 - v0) if v1 != v0 else 0.5
        out[i] = t0[i] + sgn[i] * (j + frac - half)
        strength[i] = dprof[i, max(0, j - 2) : j + 3].max()
    return out, strength


def _ramp_ratio(grey: np.ndarray, pts: np.ndarray, bright_dir: np.ndarray, near: float = 3.0, far: float = 12.0) -> float:
    """Median of ``(I(p + far u) - I(p - 4 u)) / (I(p + near u) - I(p - 4 u))`` (``u`` toward the bright side)."""
    if pts.shape[0] == 0:
        return math.nan
    u = np.asarray(bright_dir, float)
    lo = _bilinear(grey, pts[:, 0] - 4 * u[0], pts[:, 1] - 4 * u[1])
    i_n = _bilinear(grey, pts[:, 0] + near * u[0], pts[:, 1] + near * u[1]) - lo
    i_f = _bilinear(grey, pts[:, 0] + far * u[0], pts[:, 1] + far * u[1]) - lo
    ok = i_n > 0
    if not ok.any():
        return math.inf
    return float(np.median(i_f[ok] / i_n[ok]))


def _trimmed_fit(p: np.ndarray, min_points: int) -> tuple[CircleFit | None, np.ndarray]:
    if p.shape[0] < max(3, min_points):
        return None, np.zeros(p.shape[0], bool)
    try:
        f = fit_circle_taubin(p)
    except DegenerateFitError:
        return None, np.zeros(p.shape[0], bool)
    r = circle_residuals(p, f.center_rc, f.radius)
    mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    keep = np.abs(r) <= max(1.0, 3.0 * mad)
    if keep.sum() >= max(3, min_points) and not keep.all():
        try:
            f = fit_circle_taubin(p[keep])
        except DegenerateFitError:
            return None, np.zeros(p.shape[0], bool)
    else:
        keep = np.ones(p.shape[0], bool)
    return f, keep


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
    below ``min_eigen_ratio`` and :class:`~jaxlimb.errors.TooManyOutliersError`
    when fewer than ``min_points`` lines cross the lit limb.

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
    lr = _lit_region(img, region, mask, opt)
    r0, _, c0, _ = region.roi
    sun_rc = _sun_image_direction(hints, camera, pri, (lr.axes.centroid_rc[0] + r0, lr.axes.centroid_rc[1] + c0))
    axis = np.array(sun_rc) if sun_rc is not None else np.array(lr.axes.axis_rc)
    spacing = opt.spacing_frac * pri.expected_radius_px
    offsets = spacing * np.arange(-opt.n_lines_half, opt.n_lines_half + 1, dtype=float)
    tr = scan_transitions(
        lr.binary,
        lr.sub,
        lr.axes.centroid_rc,
        axis,
        offsets,
        min_correlation=opt.min_correlation,
        subpixel=opt.subpixel,
        valid_shape=img.shape,
        valid_offset=(r0, c0),
        valid_mask=None if lr.valid is None else valid_zone(lr.valid, MASK_REACH_PX),
    )
    sel = _select_lit_set(tr, lr, region, pri, axis, sun_rc is not None, opt)
    check_radius(sel.fit.radius, pri, band)

    off = np.array([r0, c0], float)
    points_full = sel.points + off
    center = (sel.fit.center_rc[0] + r0, sel.fit.center_rc[1] + c0)
    if sel.merged and sun_rc is None:
        lit_dir, half = lit_arc(points_full, center)
    else:
        lit_dir, half = lit_arc(points_full, center, sun_rc)
    info = _scan_info(pri, region, lr, sel, axis, spacing, offsets.size, off)
    info["timings_s"] = {"total": time.perf_counter() - t0}
    return LimbCandidates(
        points_rc=points_full,
        center_rc=(float(center[0]), float(center[1])),
        radius=float(sel.fit.radius),
        residual_rms=float(sel.fit.rms),
        lit_direction=lit_dir,
        lit_halfangle=half,
        front_end="scanline",
        info=info,
    )


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


def _lit_region(img: np.ndarray, region: BodyRegion, mask: np.ndarray | None, opt: ScanlineOptions) -> _LitRegion:
    """Threshold, largest filled region and its inertia axes; :class:`TooThinError` below ``min_eigen_ratio``."""
    r0, r1, c0, c1 = region.roi
    sub = img[r0:r1, c0:c1].astype(np.float32)  # exact for integer data up to 2^24
    sub_f = cv2.medianBlur(sub, opt.median_ksize) if opt.median_ksize > 1 else sub
    vsub = None if mask is None else np.asarray(mask, bool)[r0:r1, c0:c1]
    gt, low = _binary_threshold(sub_f, vsub, region.noise_sigma, opt)
    dark = region.dark_surface and low < gt  # a variegated body (crop.dark_surface_region): its low threshold
    gt = low if dark else gt
    binary = _largest_filled(_masked_binary(sub_f > gt, vsub))
    ax = inertia_axes(binary)
    if ax.eigen_ratio < opt.min_eigen_ratio:
        raise TooThinError(
            f"eigenvalue ratio lambda_min/lambda_max = {ax.eigen_ratio:.3g} of the lit region is below "
            f"min_eigen_ratio = {opt.min_eigen_ratio:g} (too thin to process)"
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


def _select_lit_set(tr, lr: _LitRegion, region: BodyRegion, pri: Prior, axis: np.ndarray, sun_known: bool,
                    opt: ScanlineOptions) -> _LitSet:
    """Entry or exit transitions as the lit limb (§VI): trimmed circle fits of both sets, the choice, the
    ramp and hard-edge checks, and the merge of a consistent other set."""
    entry, exit_ = tr.entry, tr.exit
    f_in, k_in = _trimmed_fit(entry, opt.min_points)
    f_out, k_out = _trimmed_fit(exit_, opt.min_points)
    sets = {"entry": (entry, f_in, k_in), "exit": (exit_, f_out, k_out)}
    st_in = float(np.nanmedian(tr.entry_strength[k_in])) if f_in is not None else 0.0
    st_out = float(np.nanmedian(tr.exit_strength[k_out])) if f_out is not None else 0.0
    g_ref, contrast = _edge_references(lr, region)
    lit, other, choice_reason = _choose_lit_set(f_in, f_out, st_in, st_out, sun_known, pri, opt)
    pts, fit, keep = sets[lit]
    if fit is None:
        raise TooManyOutliersError(
            f"scan lines found {pts.shape[0]} lit-limb transitions, fewer than min_points = {opt.min_points} "
            f"usable for a circle fit (is the lit limb outside the frame?)"
        )
    ramp = math.nan
    if not sun_known and sets[other][1] is None:
        bright = axis / np.linalg.norm(axis) * (1.0 if lit == "entry" else -1.0)
        ramp = _check_not_a_ramp(lr.sub, pts[keep], bright, pri.expected_radius_px, opt)
    _check_hard_edge(st_out if lit == "exit" else st_in, g_ref, contrast, opt)
    pts, fit, merged = _merge_sets(pts[keep], fit, sets[other], opt)
    info = {"lit_set": lit, "edge_step_entry": st_in, "edge_step_exit": st_out, "edge_step_reference": g_ref,
            "ramp_ratio": ramp, "merged": merged, "choice": choice_reason}
    return _LitSet(pts, fit, merged, sets[other], info)

def _check_not_a_ramp(sub: np.ndarray, pts: np.ndarray, bright: np.ndarray, R_est: float, opt: ScanlineOptions) -> float:
    """A single set and no Sun direction: a limb is a step (flat on its bright side), a terminator a ramp
    (brightness keeps rising into the body).  Returns the far/near brightness ratio.

    Raises
    ------
    TooManyOutliersError
        The ratio exceeds ``max_ramp_ratio``.
    """
    ramp = _ramp_ratio(sub, pts, bright, far=max(6.0, min(12.0, 0.15 * R_est)))
    if not ramp <= opt.max_ramp_ratio:
        raise TooManyOutliersError(
            f"only one set of scan-line transitions was found and its profile is a ramp, not a limb "
            f"(brightness ratio far/near inside = {ramp:.3g} > max_ramp_ratio = {opt.max_ramp_ratio:g}): "
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


def _check_hard_edge(st_lit: float, g_ref: float, contrast: float, opt: ScanlineOptions) -> None:
    """The chosen transitions must be a hard edge: median step >= max(``min_edge_fraction`` x the
    99.5th-percentile gradient, ``min_edge_contrast`` x the body's contrast) (TooManyOutliersError)."""
    need = max(opt.min_edge_fraction * g_ref, opt.min_edge_contrast * contrast)
    if not st_lit >= need:
        raise TooManyOutliersError(
            f"the chosen scan-line transitions are not a hard edge: median step {st_lit:.4g} DN/px is below "
            f"{need:.4g} DN/px = max(min_edge_fraction = {opt.min_edge_fraction:g} x the 99.5th-percentile "
            f"gradient {g_ref:.4g}, min_edge_contrast = {opt.min_edge_contrast:g} x the contrast {contrast:.4g}); "
            f"the lit limb is not visible (outside the frame?)"
        )


def _binary_threshold(sub_f: np.ndarray, valid: np.ndarray | None, noise_sigma: float, opt: ScanlineOptions) -> tuple[float, float]:
    """Threshold of the lit region: Eq. (10) on the valid pixels, floored at 6 sigma above the sky as in
    :func:`detect_body` (the 3x3 median leaves ~1/2 of the per-pixel noise); and the low threshold of a
    variegated body, ``sky + max(6 sigma, dark_surface_frac x range)`` (:func:`~.crop.dark_surface_region`)."""
    if valid is None or not valid.any():
        vals = sub_f
        sky = float(np.percentile(sub_f[:: max(1, sub_f.shape[0] // 200), :: max(1, sub_f.shape[1] // 200)], 2.0))
    else:
        vals = sub_f[valid]
        sky = float(np.percentile(vals[:: max(1, vals.size // 40_000)], 2.0))
    floor = sky + 6.0 * (0.5 if opt.median_ksize > 1 else 1.0) * noise_sigma
    low = max(floor, sky + opt.detect.dark_surface_frac * (float(vals.max()) - sky))
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
                    pri: Prior, opt: ScanlineOptions) -> tuple[str, str, str]:
    """Which set of transitions (``entry``/``exit`` of the lit region) is the lit limb: the Sun's side when
    known, else the clearly harder edge, else the circle closer to the expected radius with the smaller
    residual.  Returns ``(lit, other, reason)``."""
    if sun_known:
        return "exit", "entry", "Sun direction from hints: the lit limb is where the lines leave the lit region"
    if f_in is not None and f_out is not None and max(st_in, st_out) >= opt.hard_edge_ratio * min(st_in, st_out):
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


def _merge_sets(pts: np.ndarray, fit: CircleFit, other, opt: ScanlineOptions) -> tuple[np.ndarray, CircleFit, bool]:
    """Both sets in one trimmed fit when the other set's circle agrees within ``merge_tolerance_px``
    (a fully lit disc: entry and exit are both limb).  Returns ``(points, fit, merged)``."""
    o_pts, o_fit, o_keep = other
    if (
        o_fit is not None
        and abs(o_fit.radius - fit.radius) <= opt.merge_tolerance_px
        and math.hypot(o_fit.center_rc[0] - fit.center_rc[0], o_fit.center_rc[1] - fit.center_rc[1]) <= opt.merge_tolerance_px
    ):
        both = np.concatenate([pts, o_pts[o_keep]])
        f2, k2 = _trimmed_fit(both, opt.min_points)
        if f2 is not None:
            return both[k2], f2, True
    return pts, fit, False


__all__ = [
    "SCAN_MASK",
    "InertiaAxes",
    "Transitions",
    "ScanlineOptions",
    "inertia_axes",
    "scan_transitions",
    "scanline_front_end",
    "threshold_eq10",
]
