"""A picture of a ``locate`` result: the image around the body, the fitted pixels and limb, the truth, and the
image's own edge along the fitted limb's normals against that limb (:func:`edge_residuals`)."""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from .._io import atomic_path
from ..errors import LimbInputError
from ..geometry.conic import ellipse_points
from ..imaging.crop import estimate_noise
from .result import LimbMeasurement

#: A normal's edge is located only where its inner and outer levels differ by this many noise sigmas (the frame's
#: pixel-difference estimate): an unlit limb has no edge to cross.
EDGE_CONTRAST_SIGMAS = 5.0


def _limb_points(meas: LimbMeasurement, n: int = 720) -> np.ndarray:
    """Points ``(row, col)`` on the fitted limb (the ellipse if any, else the circle)."""
    t = np.linspace(0.0, 2 * np.pi, n)
    ell = meas.ellipse.to_json() if meas.ellipse is not None else meas.extras.get("limb_ellipse")
    if ell is not None:
        return ellipse_points(ell["center_rc"], ell["semi_axes_px"], ell["angle_rad"], t)
    r0, c0 = meas.center_rc
    R = float(meas.radius_px or 0.0)
    return np.stack([r0 + R * np.sin(t), c0 + R * np.cos(t)], axis=1)


def _truth_points(truth: Any, n: int = 720) -> tuple[np.ndarray | None, tuple[float, float] | None]:
    """Limb points and centre of a :class:`jaxlimb.render.RenderTruth`, a ``SunTruth`` or a dict."""
    if truth is None:
        return None, None
    t = np.linspace(0.0, 2 * np.pi, n)
    limb = getattr(truth, "limb", None)
    center = getattr(truth, "center_rc", None)
    if center is None and isinstance(truth, dict):
        center = truth.get("center_rc")
    if limb is not None:
        pts = ellipse_points(limb.center_rc, limb.semi_axes_px, limb.angle_rad, t)
        return pts, (float(center[0]), float(center[1])) if center is not None else None
    radius = getattr(truth, "radius_px", None)
    if radius is None and isinstance(truth, dict):
        radius = truth.get("radius_px")
    if center is None or radius is None:
        raise LimbInputError("`truth` needs `center_rc` and either `limb` (RenderTruth) or `radius_px`")
    r0, c0 = float(center[0]), float(center[1])
    return np.stack([r0 + radius * np.sin(t), c0 + radius * np.cos(t)], axis=1), (r0, c0)


def _crop(limb: np.ndarray, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """The limb's box plus a 10 % margin, clipped to the frame (the whole frame if empty)."""
    R, C = shape
    lo, hi = limb.min(0), limb.max(0)
    m = 0.1 * float(max(hi - lo)) + 5.0
    r0, r1 = int(max(0, math.floor(lo[0] - m))), int(min(R, math.ceil(hi[0] + m) + 1))
    c0, c1 = int(max(0, math.floor(lo[1] - m))), int(min(C, math.ceil(hi[1] + m) + 1))
    return (r0, r1, c0, c1) if (r1 > r0 and c1 > c0) else (0, R, 0, C)


def _zoom_box(img: np.ndarray, measurement: LimbMeasurement, limb: np.ndarray) -> tuple[float, float, float, float]:
    """30 x 30 px about the limb point farthest in the lit direction; without one, about the limb point of the
    strongest edge (inside minus outside, 3 px along the normal: the lit limb)."""
    d = measurement.extras.get("lit_direction_rc")
    cen = np.asarray(measurement.center_rc)
    if d is not None:
        k = int(np.argmax((limb - cen) @ np.asarray(d, float)))
    else:
        nrm = _limb_normals(limb, cen)
        inner, outer = (np.clip(np.rint(limb[:-1] + s * nrm), 0, np.asarray(img.shape) - 1).astype(int)
                        for s in (-3.0, 3.0))
        k = int(np.argmax(img[inner[:, 0], inner[:, 1]] - img[outer[:, 0], outer[:, 1]]))
    pr, pc = limb[k]
    return pr - 15, pr + 15, pc - 15, pc + 15


def _limb_normals(limb: np.ndarray, center_rc) -> np.ndarray:
    """Unit outward normals ``(row, col)`` of the closed curve ``limb`` (its last point repeats the first)."""
    p = limb[:-1]
    tan = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
    nrm = np.stack([tan[:, 1], -tan[:, 0]], axis=1)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    out = np.sum((p - np.asarray(center_rc, float)) * nrm, axis=1) >= 0
    return np.where(out[:, None], nrm, -nrm)


def edge_residuals(image: np.ndarray, measurement: LimbMeasurement, selected_pixels: np.ndarray | None = None,
                   n: int = 720, half_px: float = 6.0) -> tuple[np.ndarray, np.ndarray]:
    """The image's edge against the fitted limb, independent of any limb model: along the fitted limb's outward
    normal at ``n`` points, the position (px, positive outward) where the profile (cubic-spline samples every
    0.1 px within ``half_px``) crosses the level halfway between its inner and outer 1.5 px, the crossing nearest
    the limb, linearly interpolated.  Only points within 2 px of a fitted pixel (all when there are none) whose
    whole profile lies in the frame and whose two levels differ by :data:`EDGE_CONTRAST_SIGMAS` noise sigmas.  A
    centre error shows as a sinusoid of the position angle, a radius error as an offset; the half-level of a
    limb-darkened or -brightened edge sits off the limb by a fraction of its blur, the same all along it.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
    measurement : LimbMeasurement
        ``locate``'s answer (its ellipse, else its circle).
    selected_pixels : np.ndarray (m, 2), optional
        Fitted pixels ``(row, col)``; default ``measurement.selected_pixels_rc``.
    n : int
        Points along the limb.
    half_px : float
        Half-length of each normal profile (px).

    Returns
    -------
    angle_deg : np.ndarray (k,)
        Position angle of each kept point about the centre, counter-clockwise from +col as displayed (deg).
    residual_px : np.ndarray (k,)
        Edge minus fitted limb along the normal (px).
    """
    from scipy.ndimage import map_coordinates
    from scipy.spatial import cKDTree

    img = np.asarray(image, dtype=float)
    cen = np.asarray(measurement.center_rc, float)
    limb = _limb_points(measurement, n + 1)
    p, nrm = limb[:-1], _limb_normals(limb, cen)
    pix = measurement.selected_pixels_rc if selected_pixels is None else selected_pixels
    if pix is not None and len(pix):
        p_keep = cKDTree(np.asarray(pix, float)).query(p, distance_upper_bound=2.0)[0] < np.inf
        p, nrm = p[p_keep], nrm[p_keep]
    s = np.arange(-half_px, half_px + 1e-9, 0.1)
    pts = p[:, None, :] + s[None, :, None] * nrm[:, None, :]
    inside = np.all((pts >= 0) & (pts <= np.asarray(img.shape, float) - 1), axis=(1, 2))
    p, pts = p[inside], pts[inside]
    prof = map_coordinates(img, [pts[..., 0].ravel(), pts[..., 1].ravel()], order=3).reshape(pts.shape[:2])
    side = max(3, int(round(1.5 / (s[1] - s[0]))))
    inner, outer = prof[:, :side].mean(axis=1), prof[:, -side:].mean(axis=1)
    mid = 0.5 * (inner + outer)
    above = prof >= mid[:, None]
    cross = above[:, 1:] != above[:, :-1]
    j = np.argmin(np.where(cross, np.abs(s[:-1] + 0.5 * (s[1] - s[0]))[None, :], np.inf), axis=1)
    ok = cross[np.arange(j.size), j] & (np.abs(inner - outer) >= EDGE_CONTRAST_SIGMAS * estimate_noise(img))
    y0, y1 = prof[np.arange(j.size), j] - mid, prof[np.arange(j.size), j + 1] - mid
    res = s[j] + (s[1] - s[0]) * y0 / np.where(y0 == y1, 1.0, y0 - y1)
    p, res = p[ok], res[ok]
    ang = np.degrees(np.arctan2(-(p[:, 0] - cen[0]), p[:, 1] - cen[1])) % 360.0
    return ang, res


def _residual_panel(ax: Any, ang: np.ndarray, res: np.ndarray) -> None:
    """Edge minus fitted limb against the position angle (in (-180, 180] when the arc crosses 0), with medians in
    10-degree bins (broken where a bin has fewer than 5 normals)."""
    if ang.size and (np.ptp(ang) > 180.0) and np.ptp((ang + 180.0) % 360.0) < np.ptp(ang):
        ang = (ang + 180.0) % 360.0 - 180.0
    ax.plot(ang, res, ".", ms=2, color="0.4", alpha=0.6, label="per normal")
    lo_a = -180.0 if ang.size and ang.min() < 0 else 0.0
    bins = np.arange(lo_a, lo_a + 361.0, 10.0)
    idx = np.digitize(ang, bins) - 1
    med = np.array([float(np.median(res[idx == i])) if np.count_nonzero(idx == i) >= 5 else np.nan
                    for i in range(bins.size - 1)])
    ax.plot(0.5 * (bins[1:] + bins[:-1]), med, "o-", color="red", ms=3, lw=1.0, label="median, 10 deg bins")
    ax.axhline(0.0, color="k", lw=0.6)
    if res.size:
        lo, hi = np.percentile(res, [2, 98])
        pad = 0.2 * max(hi - lo, 0.2)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_xlim(ang.min() - 5.0, ang.max() + 5.0)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.6)
    ax.set_xlabel("position angle (deg, counter-clockwise from +col)")
    ax.set_ylabel("image edge - fitted limb (px, outward)")
    ax.set_title("the image's own edge along the limb's normals", fontsize=9)


def _panel(ax: Any, img: np.ndarray, vrange, measurement: LimbMeasurement, limb, pix, tpts, tcen, box, zoom: bool) -> None:
    """One panel: the image, the fitted pixels, the fitted and true limbs and centres, in ``box``."""
    R, C = img.shape
    zr0, zr1, zc0, zc1 = box
    ax.imshow(img, cmap="gray", vmin=vrange[0], vmax=vrange[1], interpolation="nearest", origin="upper",
              extent=(-0.5, C - 0.5, R - 0.5, -0.5))
    if pix is not None and pix.size:
        step = max(1, pix.shape[0] // (20000 if zoom else 4000))
        ax.plot(pix[::step, 1], pix[::step, 0], ",", color="yellow", alpha=0.6 if zoom else 0.35,
                label="fitted pixels" if not zoom else None)
    ax.plot(limb[:, 1], limb[:, 0], "-", color="red", lw=1.0, label="fitted limb" if not zoom else None)
    ax.plot([measurement.center_rc[1]], [measurement.center_rc[0]], "+", color="red", ms=10)
    if tpts is not None:
        ax.plot(tpts[:, 1], tpts[:, 0], "--", color="cyan", lw=0.8, label="truth" if not zoom else None)
        if tcen is not None:
            ax.plot([tcen[1]], [tcen[0]], "x", color="cyan", ms=8)
    ax.set_xlim(zc0, zc1)
    ax.set_ylim(zr1, zr0)
    ax.set_xlabel("col (px)")
    ax.set_ylabel("row (px)")


def _title(measurement: LimbMeasurement, tcen) -> str:
    """Centre, radius and, with a truth, the centre's error."""
    txt = f"centre ({measurement.center_rc[0]:.3f}, {measurement.center_rc[1]:.3f})"
    if measurement.radius_px is not None:
        txt += f", radius {measurement.radius_px:.3f} px"
    if tcen is not None:
        txt += f"\nerror vs truth: {math.hypot(measurement.center_rc[0] - tcen[0], measurement.center_rc[1] - tcen[1]):.3f} px"
    return txt


def save_locate_figure(
    image: np.ndarray,
    measurement: LimbMeasurement,
    path: str | os.PathLike[str],
    selected_pixels: np.ndarray | None = None,
    truth: Any = None,
    *,
    title: str | None = None,
    dpi: int = 120,
) -> None:
    """Save a PNG/PDF picture of ``measurement`` on ``image`` (matplotlib, Agg; atomic write).

    Left: the body, fitted pixels, limb and centre (red), truth (cyan), titled ``title`` (default: centre, radius,
    error); middle: 30 x 30 px of the lit limb; right: the image's own edge against the fitted limb
    (:func:`edge_residuals`).  A non-2-D ``image``: :class:`~jaxlimb.errors.LimbInputError`.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
    measurement : LimbMeasurement
    path : str or os.PathLike
        Output file; its suffix picks the format (default PNG).
    selected_pixels : np.ndarray (n, 2), optional
        Fitted pixels ``(row, col)``; default ``measurement.selected_pixels_rc``.
    truth : RenderTruth, SunTruth or dict, optional
        True limb and centre (a dict needs ``center_rc`` and ``radius_px``).
    title : str, optional
    dpi : int
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    img = np.asarray(image, dtype=float)
    if img.ndim != 2:
        raise LimbInputError(f"`image` must be 2-D [row, col], got shape {img.shape}")
    pix = measurement.selected_pixels_rc if selected_pixels is None else selected_pixels
    pix = None if pix is None else np.asarray(pix, dtype=float)
    limb = _limb_points(measurement)
    tpts, tcen = _truth_points(truth)
    r0, r1, c0, c1 = _crop(limb, img.shape)
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), gridspec_kw={"width_ratios": [1.6, 1, 1.3]})
    vmin, vmax = np.percentile(img[r0:r1, c0:c1], [0.5, 99.8])
    for ax, zoom in zip(axes[:2], (False, True)):
        _panel(ax, img, (vmin, vmax), measurement, limb, pix, tpts, tcen,
               _zoom_box(img, measurement, limb) if zoom else (r0 - 0.5, r1 - 0.5, c0 - 0.5, c1 - 0.5), zoom)
    axes[0].legend(loc="upper right", fontsize=8, framealpha=0.6)
    axes[1].set_title("zoom on the lit limb", fontsize=9)
    _residual_panel(axes[2], *edge_residuals(img, measurement, pix))
    axes[0].set_title(title or _title(measurement, tcen), fontsize=9)
    fig.tight_layout()
    suffix = os.path.splitext(os.fspath(path))[1] or ".png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=suffix.lstrip(".") or "png")
    plt.close(fig)


__all__ = ["edge_residuals", "save_locate_figure"]
