"""Rectification of an off-axis figure to a virtual on-axis camera, and the chamfer distance to its outline.

The templates of Wu et al. are on-axis by construction (Sec. 3.3), which the similarity principle of
Eq. (18)-(19) silently assumes.  A body far off the optical axis is therefore compared after the rotation
homography ``H = K R^T K^-1`` to a virtual camera whose boresight passes through the figure centre, which
removes the 1/cos^2 radial stretch of the pinhole (about 1 % at 8 deg off axis).  The Hu moments of
Eq. (10)-(13) of the rectified figure come from the affine approximation of ``H`` at its centre.
"""

from __future__ import annotations

import cv2
import numpy as np

from .features import (
    FigureFeatures,
    central_moments,
    elongation,
    far_point_candidates,
    hu_from_central,
    orientation,
    raw_moments_mask,
    resample_closed,
)


def rot_z_to(u: np.ndarray) -> np.ndarray:
    """Smallest rotation taking +z to the unit vector ``u``.

    Parameters
    ----------
    u : np.ndarray (3,)
        Unit vector (camera frame), e.g. a line of sight.

    Returns
    -------
    np.ndarray (3, 3)
        ``R`` with ``R @ [0, 0, 1] = u`` (Rodrigues' formula about ``z x u``); identity when ``u`` is along z.
    """
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, u)
    s = np.linalg.norm(v)
    c = float(z @ u)
    if s < 1e-15:
        return np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx * ((1 - c) / s**2)


def apply_homography(H: np.ndarray, rc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (row, col) mapped by the homography ``H`` (which acts on ``(col, row, 1)``), and the scale ``w``.

    Parameters
    ----------
    H : np.ndarray (3, 3)
        Homography on homogeneous ``(x=col, y=row, 1)``.
    rc : np.ndarray (..., 2)
        Points, px (row, col).

    Returns
    -------
    rc_mapped : np.ndarray (..., 2)
        Mapped points, px (row, col).
    w : np.ndarray (...)
        Homogeneous scale of each point.
    """
    rc = np.asarray(rc, dtype=float)
    x = np.stack([rc[..., 1], rc[..., 0], np.ones(rc.shape[:-1])], axis=-1) @ H.T
    w = x[..., 2]
    return np.stack([x[..., 1] / w, x[..., 0] / w], axis=-1), w


def affine_of(H: np.ndarray, rc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Affine approximation ``x' = A x + b`` (x = (col, row)) of the homography at ``rc`` (central differences
    of half a pixel).

    Parameters
    ----------
    H : np.ndarray (3, 3)
        Homography (:func:`apply_homography`).
    rc : np.ndarray (2,)
        Point of tangency, px (row, col).

    Returns
    -------
    A : np.ndarray (2, 2)
        Jacobian of the map in ``(x, y)``.
    b : np.ndarray (2,)
        Offset, px ``(x, y)``.
    """
    p0, _ = apply_homography(H, rc)
    e = 0.5
    px, _ = apply_homography(H, rc + np.array([0.0, e]))
    py, _ = apply_homography(H, rc + np.array([e, 0.0]))
    mx, _ = apply_homography(H, rc - np.array([0.0, e]))
    my, _ = apply_homography(H, rc - np.array([e, 0.0]))
    A = np.empty((2, 2))
    A[:, 0] = (px - mx)[::-1] / (2 * e)  # d(x', y') / dx
    A[:, 1] = (py - my)[::-1] / (2 * e)  # d(x', y') / dy
    x0 = np.asarray(rc, dtype=float)[::-1]
    b = p0[::-1] - A @ x0
    return A, b


def affine_moments(area: float, c_xy: np.ndarray, mu: np.ndarray, A: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Area, centroid and central moments (``mu20..mu03``) of a figure mapped by ``x' = A x + b``.

    Central moments are tensors: ``T'_ij = |det A| A_ia A_jb T_ab`` and likewise for order 3.

    Parameters
    ----------
    area : float
        Area of the figure (px^2).
    c_xy : np.ndarray (2,)
        Centroid ``(x, y)``.
    mu : np.ndarray (7,)
        Central moments ``mu20, mu11, mu02, mu30, mu21, mu12, mu03``.
    A, b : np.ndarray (2, 2), (2,)
        The affine map.

    Returns
    -------
    area : float
        ``|det A| area``.
    c_xy : np.ndarray (2,)
        ``A c + b``.
    mu : np.ndarray (7,)
        The mapped central moments, same order.
    """
    mu20, mu11, mu02, mu30, mu21, mu12, mu03 = mu
    T2 = np.array([[mu20, mu11], [mu11, mu02]])
    T3 = np.empty((2, 2, 2))
    T3[0, 0, 0] = mu30
    T3[0, 0, 1] = T3[0, 1, 0] = T3[1, 0, 0] = mu21
    T3[0, 1, 1] = T3[1, 0, 1] = T3[1, 1, 0] = mu12
    T3[1, 1, 1] = mu03
    d = abs(float(np.linalg.det(A)))
    T2n = d * A @ T2 @ A.T
    T3n = d * np.einsum("ia,jb,kc,abc->ijk", A, A, A, T3)
    mun = np.array([T2n[0, 0], T2n[0, 1], T2n[1, 1], T3n[0, 0, 0], T3n[0, 0, 1], T3n[0, 1, 1], T3n[1, 1, 1]])
    return area * d, A @ c_xy + b, mun


def rectified_features(mask: np.ndarray, H: np.ndarray, n_contour: int) -> tuple[FigureFeatures, np.ndarray]:
    """Features of the figure mapped by the homography ``H``.

    Moments: pixel-count moments of the mask (``cv2.moments``) transformed by the
    affine approximation of ``H`` at the figure centre (the neglected second-order
    terms are ~ (size/f) tan(off-axis angle), below 1e-3 relative for any
    reasonable field of view).  Contour: mapped exactly.

    Parameters
    ----------
    mask : np.ndarray (rows, cols)
        Binary figure.
    H : np.ndarray (3, 3)
        Rectifying homography ``K R^T K^-1`` (pixel -> virtual pixel).
    n_contour : int
        Points of the resampled contour.

    Returns
    -------
    features : FigureFeatures
        Of the rectified figure (Eq. 10-14).
    contour_xy : np.ndarray (m, 2)
        The rectified outer contour, ``(x, y)`` virtual pixels.
    """
    c0, r0, bw, bh = cv2.boundingRect(np.ascontiguousarray(mask, dtype=np.uint8))
    crop = np.ascontiguousarray(mask[r0 : r0 + bh, c0 : c0 + bw], dtype=np.uint8)
    area, xb, yb, mu = central_moments(raw_moments_mask(crop))
    c_xy = np.array([xb + c0, yb + r0])
    A, b = affine_of(H, c_xy[::-1])
    area, c, mu = affine_moments(area, c_xy, mu, A, b)
    contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    big = max(contours, key=lambda q: abs(cv2.contourArea(q))).reshape(-1, 2).astype(float) + np.array([c0, r0])
    crc, _ = apply_homography(H, big[:, ::-1])
    cxy = crc[:, ::-1]
    feats = FigureFeatures(
        area=area,
        center_rc=c[::-1].copy(),
        hu=hu_from_central(area, mu),
        orientation=orientation(mu),
        elongation=elongation(mu),
        attitude_xy=far_point_candidates(cxy, c, n=1)[0],
        contour_xy=resample_closed(cxy, n_contour) - c,
    )
    return feats, cxy


class Chamfer:
    """Distance (px) to the observed outer contour, sampled bilinearly."""

    def __init__(self, mask: np.ndarray) -> None:
        bx, by, bw, bh = cv2.boundingRect(np.ascontiguousarray(mask, dtype=np.uint8))
        pad = 8 + int(0.25 * max(bw, bh))
        self.r0 = max(by - pad, 0)
        self.c0 = max(bx - pad, 0)
        r1 = min(by + bh - 1 + pad, mask.shape[0] - 1)
        c1 = min(bx + bw - 1 + pad, mask.shape[1] - 1)
        crop = np.ascontiguousarray(mask[self.r0 : r1 + 1, self.c0 : c1 + 1], dtype=np.uint8)
        edge = np.ones_like(crop)
        contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        cv2.drawContours(edge, contours, -1, color=0, thickness=1)
        self.dt32 = cv2.distanceTransform(edge, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        self.dt = self.dt32.astype(float)

    def remap(self, rc: np.ndarray) -> np.ndarray:
        """Like ``__call__`` (without the distance outside the crop), bilinear in C (``cv2.remap``).

        Parameters
        ----------
        rc : np.ndarray (..., n, 2)
            Points, px (row, col) of the frame.

        Returns
        -------
        np.ndarray (..., n)
            Distance (px) to the outer contour at each point (edge-replicated outside the crop).
        """
        shp = rc.shape[:-1]
        flat = rc.reshape(-1, shp[-1], 2)
        mr = (flat[..., 0] - self.r0).astype(np.float32)
        mc = (flat[..., 1] - self.c0).astype(np.float32)
        out = cv2.remap(self.dt32, mc, mr, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return out.reshape(shp)

    def __call__(self, rc: np.ndarray) -> np.ndarray:
        h, w = self.dt.shape
        r = rc[..., 0] - self.r0
        c = rc[..., 1] - self.c0
        rcl = np.clip(r, 0, h - 1.000001)
        ccl = np.clip(c, 0, w - 1.000001)
        i, j = np.floor(rcl).astype(int), np.floor(ccl).astype(int)
        fr, fc = rcl - i, ccl - j
        d = self.dt
        v = (d[i, j] * (1 - fr) + d[i + 1, j] * fr) * (1 - fc) + (d[i, j + 1] * (1 - fr) + d[i + 1, j + 1] * fr) * fc
        return v + np.hypot(r - rcl, c - ccl)  # outside the crop: add the distance to it


__all__ = ["Chamfer", "affine_moments", "affine_of", "apply_homography", "rectified_features", "rot_z_to"]
