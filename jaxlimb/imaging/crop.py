r"""Body detection, region of interest and cropped-target detection.

:func:`detect_body` is the shared first step of both front ends.  It works on
a block-averaged copy of the frame (at most ``work_size`` px on a side; a
1944x2592 frame is averaged 6x6), so it costs a few milliseconds, and returns
the region of interest (ROI) in full-resolution pixels, so that the gradient
and the scan lines only touch the pixels around the body.

Steps (decisions -- the papers give only Eq. 10 of the illuminated-ellipsoid
paper and the median filter of its §VI):

1. *Noise*: :math:`\sigma` from the median absolute difference of horizontally
   adjacent pixels of the full frame (``1.4826 MAD / sqrt(2)``; robust to the
   body and to stars), scaled by ``1/f`` for the f x f block average.
2. *Smoothing*: Gaussian blur (sigma 1 px) of the block-averaged image; it
   removes the noise and attenuates isolated hot pixels / stars.
3. *No-body test*: a body needs contrast.  With ``G_min``/``G_max`` the minimum
   and maximum of the smoothed image, the frame has no body when
   ``G_max - G_min < snr_min * sigma_s`` with ``sigma_s`` the noise left after
   blurring (:math:`\sigma/(2\sqrt{\pi}\,f)`): all-black, all-white and pure-noise
   frames fail it (:class:`~jaxlimb.errors.NoBodyError`).  For pure Gaussian
   noise the range is ~9 sigma_s over 10^5 samples, hence ``snr_min = 20``.
4. *Threshold* Eq. (10) of the illuminated-ellipsoid paper,
   :math:`G_t = G_{min} + (G_{max} - G_{min})/4`, floored at 6 sigma_s above the
   sky level (2nd percentile; decision: at low contrast Eq. 10 alone lands in
   the background noise and merges noise into one large "body"), and
   8-connected components;
   the body is the component with the largest summed brightness above
   :math:`G_t` (stars and hot pixels are small components).  Its holes (dark
   maria) are filled.
5. *Checks 1-2 on the image* (only when the caller has no prior, see
   :mod:`jaxlimb.imaging.prior`): the region's extent along its major axis
   below ``min_diameter_px`` -> :class:`~jaxlimb.errors.TooSmallError`; lit
   fraction of the frame above ``max_fill_fraction`` ->
   :class:`~jaxlimb.errors.TooBigError`; twice the largest inscribed-circle
   radius (the illumination parameter :math:`p_i` measured on the image, less
   the ~1.35 sigma widening by the blur and the 25 % threshold) below
   ``min_thickness_px`` -> :class:`~jaxlimb.errors.TooThinError`.

:func:`detect_cropping` implements §3.4 of the Aerospace 2015 paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ..errors import NoBodyError, TooBigError, TooSmallError, TooThinError


#: Largest side (px) of the block-averaged working image of :func:`detect_body`.
WORK_SIZE = 512
#: Gaussian blur (px of the working image) before thresholding.
SMOOTH_SIGMA = 1.0
#: No-body test: required ``(G_max - G_min) / sigma_smoothed``.
SNR_MIN = 20.0
#: Check 1: smallest extent of the lit region (full-resolution px) ...
MIN_DIAMETER_PX = 10.0
#: ... and the largest fraction of the frame it may cover.
MAX_FILL_FRACTION = 0.9
#: Check 2: smallest illumination parameter ``p_i`` measured on the image (px).  The measured thickness cannot drop
#: below the blurred width of a line (~3.6 px for a 1 px PSF): 4 px rejects crescents thinner than ~2 px while a 6 px
#: crescent passes.  The geometric check on the hints (``p_i`` from ``sun_dir_camera``) is the exact one.
MIN_THICKNESS_PX = 4.0
#: Margin (full-resolution px) added around the region for the ROI.
MARGIN_PX = 16
#: A variegated body (:func:`dark_surface_region`): the region above the sky by ``max(6 sigma, DARK_SURFACE_FRAC x
#: range)`` replaces Eq. (10)'s when it is ``DARK_SURFACE_AREA_RATIO`` to ``DARK_SURFACE_MAX_RATIO`` times larger.
DARK_SURFACE_FRAC = 0.03
DARK_SURFACE_AREA_RATIO = 1.6
DARK_SURFACE_MAX_RATIO = 8.0


@dataclass(frozen=True)
class DetectOptions:
    """Settings of :func:`detect_body`: ``run_checks`` (the size and thickness checks; the no-body test always runs)
    and ``dark_surface`` (a variegated body's region, :func:`dark_surface_region`; off above 30 deg of phase in
    :func:`jaxlimb.pipeline.frame.candidates`).  Its numbers are the module's constants."""

    run_checks: bool = True
    dark_surface: bool = True


@dataclass(frozen=True)
class CropInfo:
    """Cropped-target detection (§3.4 of the Aerospace 2015 paper).

    Attributes
    ----------
    n_crossings
        Number of lit segments along the frame border (0 = not cropped; at most 4
        for a disk).
    sides
        Frame sides touched by the body, among ``"top"``, ``"bottom"``, ``"left"``, ``"right"``.
    border_lit_fraction
        Fraction of the border ring above the threshold.
    """

    n_crossings: int
    sides: tuple[str, ...]
    border_lit_fraction: float

    @property
    def cropped(self) -> bool:
        return self.n_crossings > 0


@dataclass(frozen=True)
class BodyRegion:
    """The lit region found by :func:`detect_body` (full-resolution pixels).

    Attributes
    ----------
    roi
        ``(r0, r1, c0, c1)``: slice bounds of the region of interest (with margin).
    threshold
        Eq. (10) threshold ``G_t`` (DN).
    background, peak
        ``G_min`` and ``G_max`` of the smoothed image (DN).
    noise_sigma
        Estimated per-pixel noise (DN).
    centroid_rc
        Centroid of the lit region (Eq. 11 of the illuminated-ellipsoid paper).
    axis_rc
        Unit vector of the region's axis of symmetry (minor axis of the spread =
        the direction of largest moment of inertia).
    eigen_ratio
        ``lambda_min / lambda_max`` of the inertia tensor (1 = disk, 0 = thin).
    extent_major_px
        Extent of the region along the major axis (px; ~ the diameter).
    thickness_px
        Twice the largest inscribed-circle radius (px; ~ p_i).
    area_px
        Area of the region (full-resolution px).
    lit_fraction
        Area over frame area.
    touches_border
        The region touches the frame edge.
    factor
        Block-averaging factor used.
    crop
        :class:`CropInfo`.
    bright_sky
        The sky is brighter than the body's darkest parts (``background`` is the border's sky level).
    """

    roi: tuple[int, int, int, int]
    threshold: float
    background: float
    peak: float
    noise_sigma: float
    centroid_rc: tuple[float, float]
    axis_rc: tuple[float, float]
    eigen_ratio: float
    extent_major_px: float
    thickness_px: float
    area_px: float
    lit_fraction: float
    touches_border: bool
    factor: int
    crop: CropInfo
    mask_small: np.ndarray = field(repr=False, compare=False, default=None)  # type: ignore[assignment]
    #: the sky was measured on the frame's border, above the body's darkest parts (:func:`detect_body`)
    bright_sky: bool = False
    #: the region is a variegated body's, found above a low threshold (:func:`dark_surface_region`)
    dark_surface: bool = False


def estimate_noise(image: np.ndarray, max_samples: int = 100_000) -> float:
    """Per-pixel noise sigma from horizontally adjacent pixels: ``1.4826 MAD(diff) / sqrt(2)``.

    Falls back to the standard deviation of the differences (divided by
    sqrt(2)) when more than half of them are zero (quantised, nearly noiseless
    data), so that a sigma of 0 is returned only for noiseless images.
    """
    a = np.asarray(image)
    step = max(1, int(a.shape[0] * a.shape[1] // max_samples))  # whole rows, evenly spaced
    step = min(step, max(1, a.shape[0] // 8))
    d = np.diff(a[::step, :].astype(np.float64, copy=False), axis=1).ravel()
    if d.size == 0:
        return 0.0
    med = float(np.median(np.abs(d - np.median(d))))
    if med > 0:
        return 1.4826 * med / math.sqrt(2)
    # quantised / noiseless: clip the edges (largest 5 %) and use the std
    ad = np.abs(d)
    q = np.quantile(ad, 0.95)
    return float(np.sqrt(np.mean(np.square(d[ad <= q]))) / math.sqrt(2))


def block_average(image: np.ndarray, f: int) -> np.ndarray:
    """f x f block mean (trailing rows/cols that do not fill a block are dropped)."""
    if f <= 1:
        return np.asarray(image, dtype=np.float32)
    R, C = (image.shape[0] // f) * f, (image.shape[1] // f) * f
    a = np.asarray(image[:R, :C])
    if a.dtype not in (np.float32, np.float64, np.uint8, np.uint16):
        a = a.astype(np.float32)
    # uint8/uint16 are averaged by OpenCV and rounded to integers (no 5-Mpixel
    # float copy); detect_body adds the rounding noise (1/12 DN^2) to its noise model
    return cv2.resize(a, (C // f, R // f), interpolation=cv2.INTER_AREA).astype(np.float32)


def detect_cropping(image: np.ndarray, threshold: float | None = None, width_frac: float = 0.01) -> CropInfo:
    """Cropped-target detection, §3.4 of the Aerospace 2015 paper.

    A rectangular ring along the frame border (``width_frac`` of each dimension,
    at least 2 px wide) is walked clockwise; the mean grey level across the ring
    width is compared with ``threshold`` (default: 1/10 of the way from the
    minimum to the maximum grey tone -- the paper's "1/10 of the maximum gray
    tone" measured above the background), and the number of lit segments
    (threshold crossings / 2) is the number of times the frame cuts the target.
    """
    a = np.asarray(image, dtype=np.float64)
    R, C = a.shape
    if threshold is None:
        lo, hi = float(a.min()), float(a.max())
        threshold = lo + 0.1 * (hi - lo)
    wr = max(2, int(round(width_frac * R)))
    wc = max(2, int(round(width_frac * C)))
    top = a[:wr, :].mean(0)
    right = a[:, C - wc :].mean(1)
    bottom = a[R - wr :, :].mean(0)[::-1]
    left = a[:, :wc].mean(1)[::-1]
    ring = np.concatenate([top, right, bottom, left])
    lit = ring > threshold
    sides = tuple(s for s, seg in zip(("top", "right", "bottom", "left"), (top, right, bottom, left)) if (seg > threshold).any())
    if lit.all():
        n = 1
    else:
        # number of rising edges around the closed ring
        n = int(np.count_nonzero(lit & ~np.roll(lit, 1)))
    return CropInfo(n_crossings=n, sides=sides, border_lit_fraction=float(lit.mean()))


def nearest_fill(image: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """``image`` with each invalid pixel of ``mask`` (``False``) replaced by its nearest valid pixel.

    What body detection sees of a masked pixel: a missing band across the disc then neither cuts the
    lit region in two nor adds an edge (masked pixels are neither limb nor background)."""
    if mask is None:
        return image
    valid = np.asarray(mask, bool)
    if valid.all() or not valid.any():
        return image
    from scipy import ndimage

    idx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return np.asarray(image)[idx[0], idx[1]]


def detect_body(image: np.ndarray, options: DetectOptions | None = None, *, sky_dn: float | None = None) -> BodyRegion:
    """Find the lit body: no-body test, threshold (Eq. 10), ROI, Checks 1-2 on the image.

    A sky brighter than the darkest part of the body (a long exposure's bias or scattered light around a
    disc whose shadowed limb is darker than it: Cassini's Mimas N1644787857) puts Eq. (10)'s threshold,
    measured from the darkest pixel, below the sky, and the "lit region" is the whole frame.  When the lit
    region exceeds ``max_fill_fraction`` and the median of the frame's border ring (:func:`border_sky`) is
    above the threshold but below mid-range, the detection is repeated with the sky at that level (``sky_dn``): threshold
    ``sky + max(6 sigma, (max - sky) / 4)``, background = sky.

    Parameters
    ----------
    image
        Validated float ``[row, col]`` image.
    options
        :class:`DetectOptions`.
    sky_dn
        The sky level (DN), when known; default: Eq. (10) from the darkest pixel.

    Raises
    ------
    NoBodyError, TooSmallError, TooBigError, TooThinError
    """
    opt = options or DetectOptions()
    a = np.asarray(image)
    R, C = a.shape
    f = max(1, int(math.ceil(max(R, C) / WORK_SIZE)))
    sm, sigma, sig_s = _smoothed_small(a, f)
    gmin, gmax = float(sm.min()), float(sm.max())
    contrast = gmax - gmin
    if not contrast > 0 or contrast < SNR_MIN * sig_s:
        raise NoBodyError(
            f"no body in the image: smoothed grey-level range {contrast:.4g} DN is below {SNR_MIN:g} "
            f"x residual noise {sig_s:.3g} DN (per-pixel noise {sigma:.3g} DN)"
        )
    if sky_dn is not None:
        gmin = float(sky_dn)  # the background level of the region (grey tones of the box filter)
    gt, dark, mask, box = _lit_region(sm, gmin, gmax, sig_s, opt, sky_dn is not None)
    region = _body_region(sm, f, (R, C), mask, box, (float(gt), gmin, gmax, contrast), float(sigma), dark,
                          sky_dn is not None)
    if opt.run_checks:
        if region.lit_fraction > MAX_FILL_FRACTION and sky_dn is None:
            b = border_sky(sm)
            # the sky itself is above the threshold, and below mid-range (a frame-filling body's border is
            # the body, near its peak): measure the body above the sky
            if gt < b < gmin + 0.5 * contrast:
                try:
                    return detect_body(image, options, sky_dn=b)
                except NoBodyError:
                    pass
        check_region(region, sky_dn)
    return region


def _body_region(sm: np.ndarray, f: int, full_shape: tuple[int, int], mask: np.ndarray, box: tuple[int, int, int, int],
                 levels: tuple[float, float, float, float], sigma: float, dark: bool, bright_sky: bool) -> BodyRegion:
    """The :class:`BodyRegion` of the lit region ``mask`` at ``box = (x, y, w, h)`` of the working image ``sm``
    (reduced ``f`` times from ``full_shape``): its ROI in the full image, shape, border contact and cropping;
    ``levels``: threshold, background, peak and contrast (DN)."""
    (x, y, w, h), (R, C) = box, full_shape
    gt, gmin, gmax, contrast = levels
    full_mask = np.zeros(sm.shape, np.uint8)
    full_mask[y : y + h, x : x + w] = mask
    shape = _region_shape(mask, x, y, f)
    touches = bool(x == 0 or y == 0 or x + w >= sm.shape[1] or y + h >= sm.shape[0])
    m = MARGIN_PX
    r0 = max(0, y * f - m)
    r1 = min(R, (y + h) * f + m + (R - (R // f) * f))
    c0 = max(0, x * f - m)
    c1 = min(C, (x + w) * f + m + (C - (C // f) * f))
    crop = detect_cropping(sm, threshold=gmin + 0.1 * contrast) if touches else CropInfo(0, (), 0.0)
    return BodyRegion(
        roi=(int(r0), int(r1), int(c0), int(c1)),
        threshold=gt,
        background=gmin,
        peak=gmax,
        noise_sigma=sigma,
        **shape,
        lit_fraction=float(shape["area_px"] / (R * C)),
        touches_border=touches,
        factor=f,
        crop=crop,
        mask_small=full_mask,
        bright_sky=bright_sky,
        dark_surface=dark,
    )


def _lit_region(sm: np.ndarray, gmin: float, gmax: float, sig_s: float, opt: DetectOptions, sky_known: bool):  # type: ignore[no-untyped-def]
    """The threshold, whether it is a variegated body's (:func:`dark_surface_region`), and the lit region
    ``(mask, (x, y, w, h))`` of the working image ``sm``.

    Eq. (10), floored at 6 sigma above the sky (2nd percentile) so that at low contrast the threshold never cuts
    into the noise of the background; with the sky known (``gmin`` is it), a quarter of the range above it."""
    contrast = gmax - gmin
    sky = float(np.percentile(sm, 2.0))
    gt = gmin + max(6.0 * sig_s, 0.25 * contrast) if sky_known else max(gmin + 0.25 * contrast, sky + 6.0 * sig_s)
    mask, box = _brightest_component(sm, (sm > gt).astype(np.uint8), gt)
    if sky_known or not opt.dark_surface:
        return gt, False, mask, box
    low = sky + max(6.0 * sig_s, DARK_SURFACE_FRAC * contrast)
    g2, mask, box = dark_surface_region(sm, gt, low, mask, box, DARK_SURFACE_AREA_RATIO, DARK_SURFACE_MAX_RATIO)
    return g2, g2 < gt, mask, box


def _smoothed_small(a: np.ndarray, f: int) -> tuple[np.ndarray, float, float]:
    """The image block-averaged by ``f`` and Gaussian-smoothed, the per-pixel noise and the noise left in it."""
    small = block_average(a, f)
    sigma = estimate_noise(a)
    sig_small = sigma / f
    if f > 1 and a.dtype in (np.uint8, np.uint16):
        sig_small = math.sqrt(sig_small**2 + 1.0 / 12.0)  # rounding of the block averages
    if SMOOTH_SIGMA > 0:
        sm = cv2.GaussianBlur(small, (0, 0), SMOOTH_SIGMA, borderType=cv2.BORDER_REPLICATE)
        return sm, sigma, sig_small / (2 * math.sqrt(math.pi) * SMOOTH_SIGMA)
    return small, sigma, sig_small


def dark_surface_region(sm: np.ndarray, gt: float, low: float, mask: np.ndarray, box: tuple, area_ratio: float,  # type: ignore[no-untyped-def]
                        max_ratio: float = math.inf, min_patches: int = 3):
    """The lit region of a variegated body: Eq. (10)'s threshold cuts at a quarter of the range between the sky
    and the brightest pixel, which on a body of one albedo is the lit disc, but on the Earth at low phase (bright
    clouds, dark oceans, Lambert limb darkening to zero at the limb) is the clouds alone: the "disc" is a cloud
    bank, its outline cloud edges (independent EPIC-like renders, benchmarks/earth_full_disc.py).  When the
    region above ``low`` (a few sigma, or a few percent of the range, above the sky) is ``area_ratio`` to
    ``max_ratio`` times larger and holds at least ``min_patches`` separate regions above ``gt`` (cloud banks), it
    is the body: ``(low, its mask, its box)``; else ``(gt, mask, box)`` unchanged (a region many times larger is
    a halo, e.g. the EUV corona of an AIA 171 frame; a thin crescent's faint horns enlarge its one patch; the
    bounds are tuned, ``docs/validation/constants.md#dark_surface``).  A Moon's maria
    (15-35 % below the highlands) or the glow of a limb never double the region; the earthshine of a crescent's
    night side (~0.1 % of the lit side) stays below ``low``."""
    if not low < gt:
        return gt, mask, box
    try:
        low_mask, low_box = _brightest_component(sm, (sm > low).astype(np.uint8), low)
    except NoBodyError:
        return gt, mask, box
    if not area_ratio * np.count_nonzero(mask) <= np.count_nonzero(low_mask) <= max_ratio * np.count_nonzero(mask):
        return gt, mask, box
    x, y, w, h = low_box
    inside = (sm[y : y + h, x : x + w] > gt) & (low_mask > 0)
    n_bright = cv2.connectedComponents(inside.astype(np.uint8), connectivity=8)[0] - 1
    if n_bright < min_patches:  # one bright region (a crescent whose faint horns the low threshold adds): not variegated
        return gt, mask, box
    return low, low_mask, low_box


def _brightest_component(sm: np.ndarray, binary: np.ndarray, gt: float) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """The connected component above the threshold with the most light above it, holes filled, in its
    bounding box ``(x, y, w, h)``; :class:`NoBodyError` when there is none."""
    n_lab, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    if n_lab <= 1:
        raise NoBodyError("no body in the image: nothing above the Eq. (10) threshold")
    weights = np.bincount(labels.ravel(), weights=(sm - gt).ravel().astype(np.float64), minlength=n_lab)
    weights[0] = -np.inf
    lab = int(np.argmax(weights))
    x, y, w, h, _area = stats[lab]
    mask = (labels[y : y + h, x : x + w] == lab).astype(np.uint8)
    # fill holes: external contour filled
    cnts, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(mask)
    cv2.drawContours(filled, cnts, -1, 1, thickness=cv2.FILLED)
    return filled, (int(x), int(y), int(w), int(h))


def _region_shape(mask: np.ndarray, x: int, y: int, f: int) -> dict[str, Any]:
    """Centroid, symmetry axis, eigenvalue ratio, extent along the major axis, thickness and area of the
    lit region (full-resolution pixels), as :class:`BodyRegion` fields."""
    rr, cc = np.nonzero(mask)
    # small-pixel (i, j) covers full rows [i f, (i+1) f): centre at i f + (f - 1)/2
    rows = (rr + y) * f + 0.5 * (f - 1)
    cols = (cc + x) * f + 0.5 * (f - 1)
    rb, cb = float(rows.mean()), float(cols.mean())
    dr, dc = rows - rb, cols - cb
    cov = np.array([[np.mean(dr * dr), np.mean(dr * dc)], [np.mean(dr * dc), np.mean(dc * dc)]])
    evals, evecs = np.linalg.eigh(cov)  # ascending
    minor = evecs[:, 0]  # axis of symmetry = largest inertia moment = smallest spread
    major = evecs[:, 1]
    proj = dr * major[0] + dc * major[1]
    dist = cv2.distanceTransform(np.pad(mask, 1), cv2.DIST_L2, 5)
    # a band W px wide has max distance ~(W + 1)/2; the blur + 25 % threshold widen
    # an edge by ~0.67 sigma on each side (removed here)
    inflation = 1.35 * SMOOTH_SIGMA if SMOOTH_SIGMA > 0 else 0.0
    return {"centroid_rc": (rb, cb), "axis_rc": (float(minor[0]), float(minor[1])),
            "eigen_ratio": float(evals[0] / evals[1]) if evals[1] > 0 else 1.0,
            "extent_major_px": float(proj.max() - proj.min() + f),
            "thickness_px": float(max(0.0, (2.0 * dist.max() - 1.0 - inflation)) * f),
            "area_px": float(rr.size) * f * f}


def border_sky(sm: np.ndarray, width_frac: float = 0.02) -> float:
    """Median of the frame's border ring (``width_frac`` of the size, >= 2 px): the sky level of a frame
    whose border is mostly sky (a body cut by one or two frame edges leaves the rest of the ring)."""
    w = max(2, int(round(width_frac * min(sm.shape))))
    ring = np.concatenate([sm[:w].ravel(), sm[-w:].ravel(), sm[w:-w, :w].ravel(), sm[w:-w, -w:].ravel()])
    return float(np.median(ring))


def check_region(region: BodyRegion, sky_dn: float | None = None) -> None:
    """Checks 1-2 measured on the image (see the module docstring)."""
    if region.lit_fraction > MAX_FILL_FRACTION:
        above = "" if sky_dn is None else f" (measured above the sky level {sky_dn:.4g} DN of the frame's border)"
        raise TooBigError(
            f"the lit region covers {100 * region.lit_fraction:.1f} % of the frame{above}, above "
            f"{100 * MAX_FILL_FRACTION:.0f} %: the body fills the image"
        )
    if region.extent_major_px < MIN_DIAMETER_PX:
        raise TooSmallError(
            f"the lit region spans {region.extent_major_px:.3g} px, below the {MIN_DIAMETER_PX:g} px a body must span"
        )
    if region.thickness_px < MIN_THICKNESS_PX:
        raise TooThinError(
            f"the lit region is {region.thickness_px:.3g} px thick at its thickest point, below "
            f"the {MIN_THICKNESS_PX:g} px a lit body must measure (new moon or thin crescent)"
        )


__all__ = [
    "BodyRegion",
    "CropInfo",
    "DetectOptions",
    "block_average",
    "border_sky",
    "check_region",
    "detect_body",
    "detect_cropping",
    "estimate_noise",
]
