r"""Front end for a predicted limb: edge search along the limb ellipse a navigation prior predicts.

When the geometry is known to a few pixels (SPICE: camera, range, body orientation and a
pointing good to tens of pixels), the limb's *shape* in the image is known -- the image
conic of the ellipsoid, :func:`jaxlimb.geometry.ellipsoid.image_conic` -- and only its
place (and, weakly, its scale) is not.  This front end uses that:

1. the predicted limb ellipse (centre, semi-axes ``a >= b``, angle ``theta``) from the
   camera and the hints ``body_radii_km``, ``range_prior_km``, ``R_body_to_camera`` and
   ``expected_center_rc`` (:func:`predicted_limb`);
2. along the outward normal of the ellipse at ``n_bins`` eccentric anomalies, the outermost
   edge of the Gaussian-smoothed image within ``search_px`` whose absolute gradient is at
   least half the largest one (a lit crescent's terminator is its inner edge; parabolic
   sub-pixel peak).  **Either polarity** counts: the lit limb (disc brighter than
   the sky) and the dark limb of a night side seen against a brighter background (the
   Cassini high-phase frames of Enceladus: E ring and plume light behind the dark disc).
   Samples near invalid pixels (:mod:`jaxlimb.imaging.formats` mask) or outside the frame
   are not used, and edges weaker than ``min_snr`` times the noise of the smoothed
   derivative are dropped;
3. the points are fitted by the ellipse of the predicted shape (``theta``, ``b/a`` held),
   centre and ``a`` free: in the frame :math:`x' = x,\ y' = y/\rho` the ellipse is a circle,
   fitted with Taubin's method (Aerospace 2015, Eq. 26-35) and a 3-MAD trim.

The result feeds the sigmoid refinement of :mod:`jaxlimb.pipeline.sphere.whole_limb`.  With a
short visible arc (a body larger than the frame) the held shape is what keeps the fit
determined.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..conics.ransac import RansacOptions, ransac_circle
from ..conics.taubin import fit_circle_taubin
from ..errors import ConfigError, TooBigError, TooManyOutliersError
from ..geometry.bodies import body_radii_km
from ..geometry.camera import Camera
from ..geometry.ellipsoid import image_conic
from ..geometry.hints import Hints
from .crop import estimate_noise
from .gradient import bilinear, strongest_pixels


@dataclass(frozen=True)
class LimbShape:
    """An ellipse in the convention of :func:`jaxlimb.models.ellipse_coords`.

    ``a`` along ``(d_row, d_col) = (-sin theta, cos theta)``, ``b = rho a`` across it.
    ``body_offset_rc``: image of the body centre minus the ellipse centre (px).
    """

    center_rc: tuple[float, float]
    a: float
    rho: float
    theta: float
    body_offset_rc: tuple[float, float] = (0.0, 0.0)

    def to_frame(self, rc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel ``(row, col)`` -> ellipse frame ``(x, y)`` (models.ellipse_coords, Eq. 19)."""
        dr = rc[..., 0] - self.center_rc[0]
        dc = rc[..., 1] - self.center_rc[1]
        ct, st = math.cos(self.theta), math.sin(self.theta)
        return dc * ct - dr * st, -dr * ct - dc * st

    def from_frame(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ellipse frame ``(x, y)`` -> pixel ``(row, col)`` (the inverse, Eq. 20)."""
        ct, st = math.cos(self.theta), math.sin(self.theta)
        return np.stack([self.center_rc[0] - x * st - y * ct, self.center_rc[1] + x * ct - y * st], axis=-1)


def predicted_limb(camera: Camera, hints: Hints, center_rc=None) -> LimbShape:
    """The limb ellipse predicted by the hints, placed so that the body centre images at ``center_rc``.

    ``center_rc`` defaults to hints ``expected_center_rc``.  Needs ``range_prior_km`` and
    radii (``body_radii_km`` or a known ``body``); ``R_body_to_camera`` (identity if absent)
    orients a triaxial body.

    Raises
    ------
    ConfigError
        The hints lack the range, the radii or the centre.
    """

    c = center_rc if center_rc is not None else hints.expected_center_rc
    if c is None or hints.range_prior_km is None or hints.body is None and hints.body_radii_km is None:
        raise ConfigError("the predicted limb needs hints expected_center_rc, range_prior_km and the body's radii")
    radii = body_radii_km(hints.body or "", radii_km=hints.body_radii_km)
    R = np.eye(3) if hints.R_body_to_camera is None else np.asarray(hints.R_body_to_camera, float)
    pin = Camera(camera.focal_length_mm, camera.pixel_pitch_mm, camera.rows, camera.cols, camera.principal_point_rc)
    q = hints.range_prior_km * pin.los(np.asarray(c, float))
    ic = image_conic(pin, radii, q, R)
    a, b = ic.semi_axes_px
    off = (ic.body_center_rc[0] - ic.center_rc[0], ic.body_center_rc[1] - ic.center_rc[1])
    return LimbShape(ic.center_rc, float(a), float(b / a), float(ic.angle_rad), off)


def _profiles(img: np.ndarray, shape: LimbShape, n_bins: int, search_px: float, step: float = 0.5):
    """Sample points ``(n_bins, n_t, 2)`` along the outward normals and the offsets ``t``."""
    phi = np.linspace(-math.pi, math.pi, n_bins, endpoint=False)
    x, y = shape.a * np.cos(phi), shape.rho * shape.a * np.sin(phi)
    nx, ny = shape.rho * np.cos(phi), np.sin(phi)  # gradient of x^2/a^2 + y^2/b^2 (up to scale)
    nn = np.hypot(nx, ny)
    nx, ny = nx / nn, ny / nn
    t = np.arange(-search_px, search_px + step / 2, step)
    pts = shape.from_frame(x[:, None] + t[None, :] * nx[:, None], y[:, None] + t[None, :] * ny[:, None])
    return pts, t


def _window(pts: np.ndarray, shape: tuple[int, int], margin: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """Rows and columns ``[lo, hi)`` of the frame within ``margin`` px of the sample points ``pts``.

    Filters whose reach is below ``margin`` give the same values at the points on this window as
    on the whole frame (the limb band of a 1944x2592 frame is a small part of it).
    """
    finite = pts[np.isfinite(pts).all(axis=-1)]
    if finite.size == 0:
        return (0, shape[0]), (0, shape[1])
    lo = np.floor(finite.min(axis=0)).astype(int) - margin
    hi = np.ceil(finite.max(axis=0)).astype(int) + margin + 1
    return ((int(np.clip(lo[0], 0, shape[0])), int(np.clip(hi[0], 0, shape[0]))),
            (int(np.clip(lo[1], 0, shape[1])), int(np.clip(hi[1], 0, shape[1]))))


def _outermost_peak(ad: np.ndarray, frac: float = 0.5) -> np.ndarray:
    """Per row, the index of the outermost local maximum of ``ad`` within ``frac`` of the row's maximum.

    The limb is the *outer* edge of the disc: inside it a lit crescent also has a terminator
    (its inner edge), which can be as steep; outside there is only sky (a glow or plume is
    gradual, far below half the limb's step)."""
    peak = np.zeros_like(ad, dtype=bool)
    peak[:, 1:-1] = (ad[:, 1:-1] >= ad[:, :-2]) & (ad[:, 1:-1] >= ad[:, 2:])
    peak &= ad >= frac * ad.max(axis=1, keepdims=True)
    last = ad.shape[1] - 1 - np.argmax(peak[:, ::-1], axis=1)
    return np.where(peak.any(axis=1), last, np.argmax(ad, axis=1))


def limb_edges(image: np.ndarray, shape: LimbShape, *, mask: np.ndarray | None = None, n_bins: int = 360,
               search_px: float = 30.0, smooth_px: float = 1.5, min_snr: float = 5.0, noise: float | None = None):
    """Edge points ``(n, 2)`` of largest |gradient| along the normals of ``shape`` and their signed steps.

    ``noise``: the frame's per-pixel noise sigma if the caller has it (default :func:`estimate_noise`).

    Returns
    -------
    points_rc, step, keep
        Points for every bin (NaN where none), the signed derivative (DN/px; > 0 where the
        disc is brighter than the sky), and the bins kept (in frame, valid, strong enough).
    """
    import cv2

    img = np.asarray(image, dtype=np.float64)
    pts, t = _profiles(img, shape, n_bins, search_px)
    R, C = img.shape
    inside = (pts[..., 0] >= 0) & (pts[..., 0] <= R - 1) & (pts[..., 1] >= 0) & (pts[..., 1] <= C - 1)
    erode = int(math.ceil(3 * smooth_px)) + 1
    (r0, r1), (c0, c1) = _window(pts, img.shape, max(int(math.ceil(4 * smooth_px)) + 2, erode + 2))
    # Gaussian of reach 4 sigma, replicated border: the same values on the window as on the frame
    sm = cv2.GaussianBlur(np.ascontiguousarray(img[r0:r1, c0:c1]), (0, 0), smooth_px, borderType=cv2.BORDER_REPLICATE)
    prof = bilinear(sm, pts[..., 0] - r0, pts[..., 1] - c0)
    d = np.gradient(prof, t, axis=1)
    bad = ~inside
    if mask is not None:  # valid pixels at least `erode` (4-connected steps) from any invalid one
        win = np.asarray(mask)[r0:r1, c0:c1].astype(np.uint8)
        kernel = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        invalid = cv2.erode(win, kernel, iterations=erode, borderType=cv2.BORDER_CONSTANT, borderValue=1) == 0
        ir = np.clip(np.rint(pts[..., 0]).astype(int), r0, r1 - 1) - r0
        ic = np.clip(np.rint(pts[..., 1]).astype(int), c0, c1 - 1) - c0
        bad |= invalid[ir, ic]
    d_ok = np.where(bad, 0.0, d)
    i = _outermost_peak(np.abs(d_ok))
    rows = np.arange(n_bins)
    peak = d_ok[rows, i]
    noise_d = (estimate_noise(img) if noise is None else noise) / (2.0 * math.sqrt(2.0 * math.pi) * smooth_px**2)  # sigma of d/dt of the smoothed noise
    ok = (np.abs(peak) >= min_snr * max(noise_d, 1e-12)) & (i > 0) & (i < len(t) - 1) & ~bad[rows, i]
    ok &= ~(bad[rows, np.clip(i - 1, 0, len(t) - 1)] | bad[rows, np.clip(i + 1, 0, len(t) - 1)])
    # parabolic sub-sample peak of |d|
    im, ip = np.clip(i - 1, 0, len(t) - 1), np.clip(i + 1, 0, len(t) - 1)
    y0, y1, y2 = np.abs(d_ok[rows, im]), np.abs(d_ok[rows, i]), np.abs(d_ok[rows, ip])
    den = y0 - 2 * y1 + y2
    frac = np.where(np.abs(den) > 1e-12, 0.5 * (y0 - y2) / np.where(np.abs(den) > 1e-12, den, 1.0), 0.0)
    tt = t[i] + np.clip(frac, -1, 1) * (t[1] - t[0])
    tn = (tt - t[0]) / (t[1] - t[0])
    lo = np.floor(tn).astype(int).clip(0, len(t) - 2)
    w = (tn - lo)[:, None]
    p = (1 - w) * pts[rows, lo] + w * pts[rows, lo + 1]
    p[~ok] = np.nan
    return p, -peak, ok


def fit_shape(points_rc: np.ndarray, shape: LimbShape, *, n_trim: int = 3, min_points: int = 12) -> tuple[LimbShape, np.ndarray]:
    """Centre and ``a`` of the ellipse of ``shape``'s axis ratio and angle through ``points_rc`` (trimmed Taubin).

    Raises
    ------
    TooManyOutliersError
        Fewer than ``min_points`` points (before or after the trim).
    """
    p = np.asarray(points_rc, float)
    p = p[np.isfinite(p).all(axis=1)]
    if p.shape[0] < min_points:
        raise TooManyOutliersError(f"only {p.shape[0]} limb edge points along the predicted limb (need >= {min_points})")
    origin = LimbShape((0.0, 0.0), shape.a, shape.rho, shape.theta)
    x, y = origin.to_frame(p)
    q = np.stack([y / shape.rho, x], axis=1)  # a circle in (y', x) coordinates
    keep = np.ones(len(q), bool)
    fit = fit_circle_taubin(q)
    for _ in range(n_trim):
        res = np.hypot(q[:, 0] - fit.center_rc[0], q[:, 1] - fit.center_rc[1]) - fit.radius
        mad = 1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep]))))
        keep = np.abs(res - np.median(res[keep])) <= max(1.0, 3.0 * mad)
        if keep.sum() < min_points:
            raise TooManyOutliersError(f"only {int(keep.sum())} consistent limb edge points (need >= {min_points})")
        fit = fit_circle_taubin(q[keep])
    y0, x0 = fit.center_rc[0] * shape.rho, fit.center_rc[1]
    c = origin.from_frame(np.array(x0), np.array(y0))
    out = LimbShape((float(c[0]), float(c[1])), float(fit.radius), shape.rho, shape.theta, shape.body_offset_rc)
    full = np.zeros(len(points_rc), bool)
    full[np.flatnonzero(np.isfinite(np.asarray(points_rc, float)).all(axis=1))[keep]] = True
    return out, full


def edge_bias_gain(points_rc: np.ndarray, shape: LimbShape) -> np.ndarray:
    """Centre shifts ``(3, 2)`` of the fixed-shape fit per px of three edge-error patterns along the arc.

    A limb model not quite the scene's places the edge ``delta(phi)`` px off, ``phi`` the
    angle around the centre.  Rows: a uniform shift (the scale absorbs it: ~0), and the
    first harmonic ``cos(phi - phi_m)``, ``sin(phi - phi_m)`` about the arc's mid-angle
    ``phi_m`` (a pure centre shift on a whole limb, amplified on a short arc where centre and
    scale trade off).
    """
    p = np.asarray(points_rc, float)
    p = p[np.isfinite(p).all(axis=1)]
    x, y = shape.to_frame(p)
    nx, ny = x / shape.a**2, y / (shape.rho * shape.a) ** 2
    nn = np.hypot(nx, ny)
    phi = np.arctan2(y, x)
    phi_m = float(np.angle(np.mean(np.exp(1j * phi))))
    base, _ = fit_shape(p, shape, n_trim=0)
    out = []
    for pattern in (np.ones_like(phi), np.cos(phi - phi_m), np.sin(phi - phi_m)):
        moved = shape.from_frame(x + pattern * nx / nn, y + pattern * ny / nn)
        b, _ = fit_shape(moved, shape, n_trim=0)
        out.append(np.subtract(b.center_rc, base.center_rc))
    return np.array(out)


def arc_center(image: np.ndarray, expected_radius_px: float, radius_uncertainty_frac: float, *,
               mask: np.ndarray | None = None, n_points: int = 3000, smooth_px: float = 1.5) -> tuple[float, float]:
    """Centre of a limb arc whose circle is larger than the frame (close approach), for the start.

    The ``n_points`` strongest gradients of the smoothed image (invalid pixels and the 3-px
    frame border left out: a frame edge is not a limb), and RANSAC with index rotation
    (:func:`jaxlimb.conics.ransac_circle`, Aerospace 2015 §5) for a circle of radius within
    ``expected_radius_px (1 -/+ 3 u)``.  The centre may lie outside the frame.

    Raises
    ------
    TooBigError
        No arc of that radius in the frame: the body fills the image and no limb is visible.
    """

    img = np.asarray(image, dtype=np.float64)
    from scipy import ndimage

    sm = ndimage.gaussian_filter(img, smooth_px, mode="nearest")
    g = np.hypot(ndimage.sobel(sm, 0), ndimage.sobel(sm, 1))
    g[:3], g[-3:], g[:, :3], g[:, -3:] = 0, 0, 0, 0
    if mask is not None:
        g[~ndimage.binary_erosion(mask, iterations=int(math.ceil(3 * smooth_px)) + 1, border_value=1)] = 0
    pts = strongest_pixels(g, n_points).astype(np.float64)
    pr, u = float(expected_radius_px), float(radius_uncertainty_frac)
    opt = RansacOptions(threshold=max(2.0, 0.01 * pr), max_tests=500, min_inliers=30, min_inlier_fraction=0.2,
                        radius_range=(pr * max(0.2, 1 - 3 * u), pr * (1 + 3 * u)))
    res = ransac_circle(pts, opt) if len(pts) >= 30 else None
    if not res or res.circle is None:
        raise TooBigError(
            f"Check 1: the expected radius {pr:.0f} px exceeds the frame and no limb arc of that radius is visible "
            f"({'no' if res is None else res.reason}): the body fills the image")
    return (float(res.circle.center_rc[0]), float(res.circle.center_rc[1]))


__all__ = ["LimbShape", "arc_center", "edge_bias_gain", "fit_shape", "limb_edges", "predicted_limb"]
