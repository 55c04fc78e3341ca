"""Independent check of a rendered limb against a conic: strip integrals of the pixel coverage.

For a convex body and a row ``r`` whose strip ``[r-0.5, r+0.5]`` lies strictly between
the top and bottom of the limb ellipse, the coverage summed over the pixels left of the
column boundary ``J0 + 1/2`` (inside the disk) equals ``J0 + 1/2 - <x_left>``, where
``<x_left>`` is the mean over the strip of the left limb column (area of the disk within
the strip, left of the boundary).  The same holds on the right and, by columns, on the
top and bottom.  Comparing with the exact strip mean of the conic's roots (Gauss--Legendre)
measures the rendered limb position to ~1e-3 px without any edge-model assumption.

The image must contain the whole disk (``truth.crop == "none"``) and hold the coverage,
i.e. be rendered with the ``"uniform"`` reflectance, no PSF and no noise
(:func:`jaxlimb.render.raytrace.render_radiance` gives exactly that).
"""

from __future__ import annotations

import numpy as np

from ..geometry.conic import conic_to_ellipse
from ..geometry.ellipsoid import ImageConic

__all__ = ["limb_accuracy", "limb_strip_errors"]


def _roots_along(C: np.ndarray, fixed: np.ndarray, axis: str) -> tuple[np.ndarray, np.ndarray]:
    """Roots of the conic (order [col, row, 1]) along col (axis='row' fixed rows) or along row."""
    if axis == "row":  # fixed row r, solve for c
        r = fixed
        A = C[0, 0]
        B = 2 * (C[0, 1] * r + C[0, 2])
        Cc = C[1, 1] * r * r + 2 * C[1, 2] * r + C[2, 2]
    else:  # fixed col c, solve for r
        c = fixed
        A = C[1, 1]
        B = 2 * (C[0, 1] * c + C[1, 2])
        Cc = C[0, 0] * c * c + 2 * C[0, 2] * c + C[2, 2]
    disc = B * B - 4 * A * Cc
    s = np.sqrt(disc)
    x1, x2 = (-B - s) / (2 * A), (-B + s) / (2 * A)
    return np.minimum(x1, x2), np.maximum(x1, x2)


def limb_strip_errors(img: np.ndarray, C: np.ndarray, row0: int = 0, col0: int = 0, margin: float = 2.0) -> np.ndarray:
    """Measured minus exact strip-mean limb positions (px) for all usable rows and columns.

    ``img`` holds coverage (1 inside, 0 outside); ``img[i, j]`` is pixel ``(row0 + i, col0 + j)``;
    ``C`` the conic (order ``[col, row, 1]``).  Returns a 1-D array: (left, right) per usable row,
    then (top, bottom) per usable column.  In each strip the split between the two sides is the pixel boundary nearest the
    chord's midpoint; strips where that boundary is not at least 1 px inside the conic over the
    whole strip, or within ``margin`` px of the conic's extremes, are skipped.
    """
    rc, ax, th = conic_to_ellipse(C)
    bbox = ImageConic(C, rc, ax, th, rc, np.eye(3)).bbox_rc()
    e_rows = _side_errors(img, C, bbox, margin, row0, col0, rows=True)
    e_cols = _side_errors(img, C, bbox, margin, row0, col0, rows=False)
    return np.concatenate([e_rows.ravel(), e_cols.ravel()])


def limb_accuracy(window, conic: np.ndarray | None = None, margin: float = 2.0) -> dict[str, float]:
    """Summary of :func:`limb_strip_errors` for a :class:`~jaxlimb.render.raytrace.RadianceWindow`
    rendered with the ``"uniform"`` reflectance (coverage image), against ``conic`` (default: the
    window's own limb conic, i.e. Eq. 2 of Mortari et al. 2016).

    Returns ``rms_px`` (per strip), ``max_px``, ``mean_px`` and the mean of each side
    (``left``/``right`` on rows, ``top``/``bottom`` on columns) -- the side means are the
    rendered limb's offsets from the conic, the quantities a limb fit would see.
    """
    C = window.limb.conic if conic is None else np.asarray(conic, dtype=float)
    center_rc, ax, th = conic_to_ellipse(C)
    bb = ImageConic(C, center_rc, ax, th, center_rc, np.eye(3)).bbox_rc()  # of the tested conic
    img, r0, c0 = window.image, window.row0, window.col0
    e_rows = _side_errors(img, C, bb, margin, r0, c0, rows=True)
    e_cols = _side_errors(img, C, bb, margin, r0, c0, rows=False)
    e = np.concatenate([e_rows.ravel(), e_cols.ravel()])
    return {
        "n_strips": float(len(e)),
        "rms_px": float(np.sqrt(np.mean(e**2))),
        "max_px": float(np.max(np.abs(e))),
        "mean_px": float(np.mean(e)),
        "left_px": float(np.mean(e_rows[:, 0])),
        "right_px": float(np.mean(e_rows[:, 1])),
        "top_px": float(np.mean(e_cols[:, 0])),
        "bottom_px": float(np.mean(e_cols[:, 1])),
    }


def _side_errors(img, C, bbox, margin, row0, col0, rows: bool) -> np.ndarray:
    """(n, 2) errors: (left, right) per row if ``rows`` else (top, bottom) per column."""
    if rows:
        return _strip(img, C, bbox, margin, row0, col0)
    C2 = C[[1, 0, 2]][:, [1, 0, 2]]  # swap the roles of row and col
    rmin, rmax, cmin, cmax = bbox
    return _strip(img.T, C2, (cmin, cmax, rmin, rmax), margin, col0, row0)


def _strip(img, C, bbox, margin, row0, col0) -> np.ndarray:
    xg, wg = np.polynomial.legendre.leggauss(16)
    rmin, rmax, _, _ = bbox
    out = []
    nc = img.shape[1]
    for i in range(img.shape[0]):
        r = row0 + i
        if r - 0.5 < rmin + margin or r + 0.5 > rmax - margin:
            continue
        ys = np.concatenate([r + 0.5 * xg, [r - 0.5, r + 0.5]])
        lo, hi = _roots_along(C, ys, "row")
        mid = 0.5 * (np.mean(lo[:-2]) + np.mean(hi[:-2]))
        J = int(np.floor(mid)) - col0  # boundary between pixel J and J + 1 (local indices)
        bnd = col0 + J + 0.5
        if not (np.max(lo) < bnd - 1.0 and np.min(hi) > bnd + 1.0) or J < 0 or J + 1 >= nc:
            continue
        ml = bnd - img[i, : J + 1].sum()
        mr = bnd + img[i, J + 1 :].sum()
        out.append((ml - 0.5 * np.sum(wg * lo[:-2]), mr - 0.5 * np.sum(wg * hi[:-2])))
    return np.asarray(out).reshape(-1, 2)
