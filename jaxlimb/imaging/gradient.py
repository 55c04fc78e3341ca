r"""The image gradient of the gradient front end (Aerospace 2015 §4, Eq. 18-22) and its pixel operators.

Richardson extrapolation (Eq. 20-22) is applied to the two derivative *components* (linear in the image, one 9-tap
kernel per axis, ``(16 k_h - k_2h)/15``), then the magnitude (Eq. 19) is taken.  The paper extrapolates the
magnitude; both cancel the h^4 term where the gradient is non-zero, but the component form is a plain linear filter
(one OpenCV call per axis) and has no bias at low gradient.  The strongest pixels are refined to sub-pixel position
along the gradient direction (a parabola through three samples; not in the paper: it removes the +-0.5 px
quantisation of pixel positions from the initial circle)."""

from __future__ import annotations

import cv2
import numpy as np

from ..errors import ConfigError


# 4-point central difference, Eq. (18), step h (offsets -2..2) and step 2h (offsets -4..4)
_K_H = np.array([0, 0, 1, -8, 0, 8, -1, 0, 0], dtype=np.float64) / 12.0


_K_2H = np.array([1, 0, -8, 0, 0, 0, 8, 0, -1], dtype=np.float64) / 24.0


#: Richardson-extrapolated kernel, Eq. (22): g = g_h + (g_h - g_2h) / (2^4 - 1)
RICHARDSON_KERNEL = _K_H + (_K_H - _K_2H) / 15.0


#: Plain four-point kernel, Eq. (18)
FOUR_POINT_KERNEL = _K_H


def richardson_gradient(image: np.ndarray, *, richardson: bool = True, border: int = 4, dtype=np.float64):
    """Image gradient by four-point central differences (Eq. 18) with one Richardson step (Eq. 20-22).

    Parameters
    ----------
    image
        2-D float array.
    richardson
        Apply the Richardson extrapolation (default); ``False`` gives Eq. (18)-(19) only.
    border
        Width of the frame band set to zero (the 9-tap kernel is invalid there).
    dtype
        ``np.float64`` (default) or ``np.float32`` (twice as fast; the front end uses
        it only to *select* candidate pixels, where 7 significant digits are ample).

    Returns
    -------
    g, g_r, g_c : arrays
        Magnitude (Eq. 19), row derivative and column derivative (grey levels per px).
    """
    dt = np.dtype(dtype)
    if dt not in (np.dtype(np.float64), np.dtype(np.float32)):
        raise ConfigError(f"richardson_gradient dtype must be float32 or float64, got {dtype!r}")
    a = np.asarray(image, dtype=dt)
    depth = cv2.CV_64F if dt == np.float64 else cv2.CV_32F
    k = (RICHARDSON_KERNEL if richardson else FOUR_POINT_KERNEL).astype(dt)
    one = np.array([1.0], dtype=dt)
    gc = cv2.sepFilter2D(a, depth, k, one, borderType=cv2.BORDER_REPLICATE)
    gr = cv2.sepFilter2D(a, depth, one, k, borderType=cv2.BORDER_REPLICATE)
    # not cv2.magnitude: its SIMD body and scalar tail round x*x + y*y differently (FMA), and where the
    # split falls depends on the arrays' memory alignment -- the same image gave ULP-different magnitudes
    # from one call to the next, and borderline decisions downstream flipped with the process's history
    g = np.sqrt(gr * gr + gc * gc)
    if border > 0:
        b = int(border)
        for arr in (g, gr, gc):
            arr[:b, :] = 0
            arr[-b:, :] = 0
            arr[:, :b] = 0
            arr[:, -b:] = 0
    return g, gr, gc


def strongest_pixels(g: np.ndarray, n: int) -> np.ndarray:
    """``(m, 2)`` integer ``(row, col)`` of the ``m = min(n, #nonzero)`` largest values, in decreasing order."""
    flat = g.ravel()
    n = int(n)
    if n <= 0:
        return np.zeros((0, 2), dtype=np.int64)
    idx = None
    if flat.size > 50 * n:
        # fast path: a threshold from a strided subsample keeps ~2n candidates
        step = max(1, flat.size // 200_000)
        sample = flat[::step]
        k = max(0, sample.size - 1 - int(2 * n * sample.size / flat.size) - 1)
        thr = np.partition(sample, k)[k]
        cand = np.flatnonzero(flat > thr) if thr > 0 else None
        if cand is not None and cand.size >= n:
            idx = cand[np.argpartition(flat[cand], cand.size - n)[cand.size - n :]]
    if idx is None:
        n = int(min(n, np.count_nonzero(flat > 0)))
        if n <= 0:
            return np.zeros((0, 2), dtype=np.int64)
        idx = np.argpartition(flat, flat.size - n)[flat.size - n :]
    idx = idx[flat[idx] > 0]
    idx = idx[np.argsort(-flat[idx], kind="stable")]
    return np.stack(np.unravel_index(idx, g.shape), axis=1).astype(np.int64)


def bilinear(img: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``img`` at ``(r, c)``, coordinates clamped to the image (edge values outside;
    ``scipy.ndimage.map_coordinates(order=1, mode="nearest")`` to rounding)."""
    R, C = img.shape
    r = np.clip(r, 0, R - 1)
    c = np.clip(c, 0, C - 1)
    i = np.minimum(np.floor(r).astype(np.int64), max(R - 2, 0))
    j = np.minimum(np.floor(c).astype(np.int64), max(C - 2, 0))
    fr, fc = r - i, c - j
    i1, j1 = np.minimum(i + 1, R - 1), np.minimum(j + 1, C - 1)
    top = (1 - fc) * img[i, j] + fc * img[i, j1]
    bottom = (1 - fc) * img[i1, j] + fc * img[i1, j1]
    return (1 - fr) * top + fr * bottom


def subpixel_refine(g: np.ndarray, gr: np.ndarray, gc: np.ndarray, points_rc: np.ndarray, max_shift: float = 1.0):
    """Move integer edge pixels to the gradient-magnitude peak along the gradient direction.

    A parabola through ``g(p - u), g(p), g(p + u)`` (``u`` the unit gradient
    direction, bilinear samples) gives the offset, clipped to ``+-max_shift`` px.
    """
    p = np.asarray(points_rc, dtype=np.float64)
    if p.size == 0:
        return p
    ir, ic = points_rc[:, 0], points_rc[:, 1]
    ur, uc = gr[ir, ic], gc[ir, ic]
    nn = np.hypot(ur, uc)
    nn = np.where(nn > 0, nn, 1.0)
    ur, uc = ur / nn, uc / nn
    g0 = g[ir, ic]
    gm = bilinear(g, p[:, 0] - ur, p[:, 1] - uc)
    gp = bilinear(g, p[:, 0] + ur, p[:, 1] + uc)
    den = gm - 2 * g0 + gp
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(den < 0, 0.5 * (gm - gp) / den, 0.0)
    t = np.clip(np.nan_to_num(t), -max_shift, max_shift)
    return np.stack([p[:, 0] + t * ur, p[:, 1] + t * uc], axis=1)


__all__ = ["FOUR_POINT_KERNEL", "RICHARDSON_KERNEL", "bilinear", "richardson_gradient", "strongest_pixels", "subpixel_refine"]
