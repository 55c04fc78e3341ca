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
  texture.  The chosen set must be a hard edge (:data:`MIN_EDGE_FRACTION`) or a
  :class:`~jaxlimb.errors.TooManyOutliersError` is raised -- a terminator is
  never returned as the limb.  When only one set exists (the other side cut by
  the frame) and no Sun direction is known, the set must also look like a limb
  on its bright side (:data:`MAX_RAMP_RATIO`).  When both sets agree (full disk) they
  are merged.
* Each set is trimmed once at ``max(1 px, 3 x 1.4826 MAD)`` of its residuals before
  the final fit (a crater or a horn can spoil a single line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..conics.taubin import CircleFit, DegenerateFitError, circle_residuals, fit_circle_taubin
from ..errors import TooThinError
from .gradient import bilinear


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


def largest_filled(binary: np.ndarray) -> np.ndarray:
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
    m = np.repeat([-1.0, 1.0], 4)  # the 8-pixel mask of §VI, (0, 0, 0, 0, 1, 1, 1, 1), as -1 / +1
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


def masked_binary(binary: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
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
    prof = bilinear(grey, pr, pc)
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


def ramp_ratio(grey: np.ndarray, pts: np.ndarray, bright_dir: np.ndarray, near: float = 3.0, far: float = 12.0) -> float:
    """Median of ``(I(p + far u) - I(p - 4 u)) / (I(p + near u) - I(p - 4 u))`` (``u`` toward the bright side)."""
    if pts.shape[0] == 0:
        return math.nan
    u = np.asarray(bright_dir, float)
    lo = bilinear(grey, pts[:, 0] - 4 * u[0], pts[:, 1] - 4 * u[1])
    i_n = bilinear(grey, pts[:, 0] + near * u[0], pts[:, 1] + near * u[1]) - lo
    i_f = bilinear(grey, pts[:, 0] + far * u[0], pts[:, 1] + far * u[1]) - lo
    ok = i_n > 0
    if not ok.any():
        return math.inf
    return float(np.median(i_f[ok] / i_n[ok]))


def trimmed_fit(p: np.ndarray, min_points: int) -> tuple[CircleFit | None, np.ndarray]:
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


__all__ = ["InertiaAxes", "Transitions", "inertia_axes", "scan_transitions", "threshold_eq10"]
