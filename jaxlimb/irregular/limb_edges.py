r"""The centre from the lit limb's edge positions alone: a second estimate, blind to the surface's albedo.

The render-and-register fit (:mod:`.register`, beyond Wu et al.) explains every pixel of the window by
``a M + b``: a surface whose albedo varies (the independent renders of
``benchmarks/irregular_independent.py``: 15-35 % value noise) changes the *contrast* of the outline from
place to place, and an intensity fit that does not know it moves the outline, and the centre, toward the
bright patches (``benchmarks/irregular_known_ablation.py``: at 90 deg phase, median 0.091 -> 0.049 px with
the albedo removed).  The *position* of an edge does not depend on its contrast.  Here, at the converged
registration:

1. points on the model's outline (coverage 1/2) whose model radiance just inside is at least
   ``lit_frac`` of the body's (the lit limb, not the dark limb or the terminator), with the outward
   normals ``n_i``;
2. the profiles of the fitted model ``F`` and of the frame ``I`` along each normal (``+-half_px``,
   bilinear), and the 1-D shift ``d_i`` of each by linear least squares with its own gain and offset,

   .. math::  I(s) \approx \alpha_i F(s) + \beta_i - \alpha_i d_i F'(s),

   so that a local albedo (``alpha_i``) does not move the edge;
3. the centre shift ``delta`` from ``d_i \approx n_i \cdot delta`` by iteratively reweighted least squares
   (Huber, ``1.5`` robust sigmas); the scale stays the registration's (at 90 deg the lit limb is half an
   outline, and a shift toward the Sun and a scale are nearly the same motion of it).

Its covariance is the cluster-robust sandwich over 16 position-angle sectors
(:func:`jaxlimb.model_error.sector_groups`) plus ``floor_px`` per axis, and the answer of
:func:`.register.register_known_attitude` is the information-weighted mean of both estimates
(:func:`combine`).
"""

from __future__ import annotations

import cv2
import numpy as np

from ..model_error import sector_groups


def _sample(a: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``a`` at ``(r, c)`` (edge pixels replicated)."""
    return cv2.remap(a.astype(np.float32), c.astype(np.float32), r.astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE).astype(float)  # fmt: skip


def outline_points(coverage: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and outward unit normals along the outer contours of ``coverage > 1/2``.

    Parameters
    ----------
    coverage : np.ndarray (h, w)
        Model coverage in the window (0..1).

    Returns
    -------
    points, normals : np.ndarray (n, 2)
        Contour pixels and outward unit normals (from the blurred coverage's gradient), (row, col) window pixels.
    """
    contours, _ = cv2.findContours((coverage > 0.5).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return np.zeros((0, 2)), np.zeros((0, 2))
    pts = np.concatenate([c[:, 0, ::-1] for c in contours]).astype(int)
    gr, gc = np.gradient(cv2.GaussianBlur(coverage.astype(float), (0, 0), 1.5))
    n = -np.stack([gr[pts[:, 0], pts[:, 1]], gc[pts[:, 0], pts[:, 1]]], axis=1)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-6
    return pts[ok].astype(float), n[ok] / norm[ok, None]


def profile_shifts(F: np.ndarray, I: np.ndarray, pts, nv, lit_level: float, half_px: float = 5.0, ds: float = 0.5):  # type: ignore[no-untyped-def]
    """Step 2 of the module docstring: the shift of the frame's edge over the model's along each normal.

    Parameters
    ----------
    F, I : np.ndarray (h, w)
        Fitted model image and frame on the window.
    pts, nv : np.ndarray (n, 2)
        Outline points and outward unit normals (:func:`outline_points`).
    lit_level : float
        Rise (DN) of the model profile inside the outline that marks a lit limb point.
    half_px, ds : float
        Half-length of the profiles and their sampling step, px.

    Returns
    -------
    d : np.ndarray (k,)
        Shift (px, along the outward normal) of the frame's edge over the model's at each kept point.
    keep : np.ndarray (k,) of int
        Indices of those points in ``pts``.
    """
    s = np.arange(-half_px, half_px + 1e-9, ds)
    R = pts[:, :1] + s[None] * nv[:, :1]
    C = pts[:, 1:] + s[None] * nv[:, 1:]
    h, w = F.shape
    inside = (R.min(1) > 1) & (C.min(1) > 1) & (R.max(1) < h - 2) & (C.max(1) < w - 2)
    f, g = _sample(F, R, C), _sample(I, R, C)
    lit = inside & (f[:, s <= -2.0].max(1) - f[:, -1] > lit_level)
    f, g = f[lit], g[lit]
    A = np.stack([f, np.ones_like(f), -np.gradient(f, ds, axis=1)], axis=2)  # (n, len(s), 3)
    N = np.einsum("nsi,nsj->nij", A, A)
    ok = np.abs(np.linalg.det(N)) > 1e-12 * np.einsum("nii->n", N) ** 3
    coef = np.zeros((len(f), 3))
    coef[ok] = np.linalg.solve(N[ok], np.einsum("nsi,ns->ni", A[ok], g[ok])[..., None])[..., 0]
    good = ok & (coef[:, 0] > 0.3)
    d = np.where(good, coef[:, 2] / np.where(good, coef[:, 0], 1.0), np.nan)
    good &= np.abs(d) < 2.0
    return d[good], np.nonzero(lit)[0][good]


def robust_shift(d: np.ndarray, X: np.ndarray, groups: np.ndarray, n_groups: int, huber: float = 1.5):  # type: ignore[no-untyped-def]
    """Step 3: the centre shift ``delta`` from ``d ~ X delta`` by Huber IRLS, with its sandwich covariance.

    Parameters
    ----------
    d : np.ndarray (k,)
        Edge shifts (px).
    X : np.ndarray (k, 2)
        Outward normals of the edge points.
    groups, n_groups : np.ndarray (k,) of int, int
        Position-angle sector of each point and the number of sectors (the clusters of the sandwich).
    huber : float
        Huber threshold in robust sigmas.

    Returns
    -------
    delta : np.ndarray (2,)
        Centre shift, px (row, col).
    cov : np.ndarray (2, 2)
        Cluster-robust sandwich covariance, px^2.
    sigma : float
        Robust (MAD) sigma of the residuals, px.
    """
    w = np.ones(len(d))
    for _ in range(10):
        sol = np.linalg.lstsq(X * np.sqrt(w)[:, None], d * np.sqrt(w), rcond=None)[0]
        r = d - X @ sol
        sig = 1.4826 * float(np.median(np.abs(r))) + 1e-9
        w = np.minimum(1.0, huber * sig / np.maximum(np.abs(r), 1e-12))
    r = d - X @ sol
    Hinv = np.linalg.inv((X * w[:, None]).T @ X)
    u = np.zeros((n_groups, X.shape[1]))
    np.add.at(u, groups, X * (w * r)[:, None])
    return sol, Hinv @ (u.T @ u) @ Hinv, sig


def lit_limb_center(F, I, coverage, P_win, lit_frac: float = 0.3, half_px: float = 5.0, n_sectors: int = 16,
                    min_points: int = 30):  # type: ignore[no-untyped-def]  # fmt: skip
    """The module docstring's estimate of the centre from the lit limb's edge positions.

    Parameters
    ----------
    F : np.ndarray (h, w)
        The fitted model image at the centre ``P_win`` (blurred by the estimated PSF, with its background).
    I : np.ndarray (h, w)
        The frame on the same window.
    coverage : np.ndarray (h, w)
        The model's (blurred) coverage.
    P_win : np.ndarray (2,)
        Body-centre image, window pixels (row, col).
    lit_frac, half_px, n_sectors, min_points : float, float, int, int
        Lit-limb level (fraction of the body's contrast: 95th percentile minus the sky), profile half-length
        (px), sectors of the sandwich and the fewest usable edge points.

    Returns
    -------
    tuple or None
        ``(P, covariance, scatter_px, n_points)``: centre (window pixels), its 2x2 covariance (px^2), the robust
        scatter of the edge shifts (px) and the points used; ``None`` with fewer than ``min_points``.
    """
    pts, nv = outline_points(coverage)
    if len(pts) < min_points:
        return None
    body = F[coverage > 0.9]
    if body.size == 0:
        return None
    sky = float(np.median(F[coverage < 0.1])) if np.any(coverage < 0.1) else 0.0
    d, keep = profile_shifts(F, I, pts, nv, lit_frac * (float(np.percentile(body, 95)) - sky), half_px)
    if len(d) < min_points:
        return None
    groups = sector_groups(pts[keep], np.asarray(P_win, dtype=float), n_sectors)
    delta, cov, sig = robust_shift(d, nv[keep], groups, n_sectors)
    return np.asarray(P_win, dtype=float) + delta, cov, sig, len(d)


def combine(P1, C1, P2, C2):  # type: ignore[no-untyped-def]
    """Information-weighted mean of two estimates and its covariance.

    Parameters
    ----------
    P1, C1 : np.ndarray (n,), (n, n)
        First estimate and its covariance.
    P2, C2 : np.ndarray (n,), (n, n)
        Second estimate and its covariance.

    Returns
    -------
    P : np.ndarray (n,)
        ``C (C1^-1 P1 + C2^-1 P2)``.
    C : np.ndarray (n, n)
        ``(C1^-1 + C2^-1)^-1``.
    """
    W1, W2 = np.linalg.inv(C1), np.linalg.inv(C2)
    C = np.linalg.inv(W1 + W2)
    return C @ (W1 @ P1 + W2 @ P2), C


__all__ = ["combine", "lit_limb_center", "outline_points", "profile_shifts", "robust_shift"]

