r"""Algebraic circle and ellipse fits, and geometric residuals.

Circle: Taubin's fit, Eq. (26)-(35) of Christian/Mortari et al., *Aerospace* 2015,
"Moon ... gradient, RANSAC, circular sigmoid" (the formalism of Al-Sharadqah &
Chernov).  With :math:`z = x^2 + y^2` the circle is :math:`a z + b x + c y + d = 0`
(Eq. 26); Taubin minimises :math:`\sum (a z_i + b x_i + c y_i + d)^2` subject to
:math:`4 a^2 \bar z + 4 a b \bar x + 4 a c \bar y + b^2 + c^2 = 1` (Eq. 28-29), the
generalised eigenproblem :math:`M A = \eta N A` (Eq. 31-34) whose smallest
non-negative eigenvalue gives the fit (Eq. 35).

Decision (numerics): the paper solves the cubic characteristic polynomial of
Eq. (34).  We solve the *same* problem in the centred frame
(:math:`\bar x = \bar y = 0`), where the constraint of Eq. (29) becomes
:math:`4 a^2 \bar z + b^2 + c^2 = 1`; substituting :math:`a' = 2\sqrt{\bar z}\, a`
and eliminating :math:`d = -a \bar z` turns Eq. (34) into an ordinary least
singular vector of the n x 3 matrix :math:`[(z-\bar z)/(2\sqrt{\bar z}), x, y]`
(Chernov's "Taubin SVD").  It is algebraically identical to Eq. (34)-(35), but
exact to rounding (the tests recover an exact circle to 1e-9 px) and immune to the
ill-conditioning of the cubic for nearly-collinear arcs.

Ellipse: the direct least-squares fit of Fitzgibbon, Pilu & Fisher (1999) in the
numerically stable form of Halir & Flusser (1998), on centred and scaled data.
It always returns an ellipse (the constraint :math:`4AC - B^2 = 1`) and is meant
as the initial conic of the Earth's elliptical sigmoid fit.

All functions take points as ``(n, 2)`` arrays of ``(row, col)`` pixel
coordinates (docs/design.md) and are pure NumPy (fast for the few hundred to few
thousand candidate points of a front end).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import LimbInputError


class DegenerateFitError(LimbInputError):
    """The points do not determine the conic (too few, coincident or collinear)."""

    check = "degenerate_fit"


@dataclass(frozen=True)
class CircleFit:
    """A fitted circle.

    Attributes
    ----------
    center_rc
        Centre ``(row, col)`` in pixels.
    radius
        Radius in pixels.
    rms
        Root-mean-square geometric residual :math:`|p_i - c| - r` of the fitted points (px).
    max_abs
        Largest absolute geometric residual (px) ("worst residual" of the paper's Fig. 10).
    n
        Number of points fitted.
    """

    center_rc: tuple[float, float]
    radius: float
    rms: float
    max_abs: float
    n: int

    @property
    def center(self) -> np.ndarray:
        """Centre as a NumPy array ``[row, col]``."""
        return np.array(self.center_rc, dtype=float)


@dataclass(frozen=True)
class EllipseFit:
    """A fitted ellipse.

    Attributes
    ----------
    center_rc
        Centre ``(row, col)`` in pixels.
    semi_axes
        ``(a, b)`` with ``a >= b`` in pixels.
    angle_rad
        Angle of the semi-major axis measured from the ``+col`` axis toward
        ``+row``, in ``(-pi/2, pi/2]`` (the image-plane angle of docs/design.md's
        ``ellipse.angle_rad``).
    conic
        Normalised conic coefficients ``(A, B, C, D, E, F)`` of
        ``A c^2 + B c r + C r^2 + D c + E r + F = 0`` (``c`` = col, ``r`` = row).
    rms, max_abs
        Geometric (orthogonal-distance) residual statistics of the fitted points (px).
    n
        Number of points fitted.
    """

    center_rc: tuple[float, float]
    semi_axes: tuple[float, float]
    angle_rad: float
    conic: tuple[float, float, float, float, float, float]
    rms: float
    max_abs: float
    n: int


def _as_points(points_rc: np.ndarray, min_n: int, what: str) -> np.ndarray:
    p = np.asarray(points_rc, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise DegenerateFitError(f"{what}: points_rc must have shape (n, 2) as (row, col), got {p.shape}")
    if p.shape[0] < min_n:
        raise DegenerateFitError(f"{what}: needs at least {min_n} points, got {p.shape[0]}")
    if not np.isfinite(p).all():
        raise DegenerateFitError(f"{what}: points_rc contains NaN/inf")
    return p


# ============================================================================ circle
def circle_residuals(points_rc: np.ndarray, center_rc, radius: float) -> np.ndarray:
    """Signed geometric distances ``|p - c| - r`` (px) of points to a circle (positive outside)."""
    p = np.asarray(points_rc, dtype=np.float64)
    c = np.asarray(center_rc, dtype=np.float64)
    return np.hypot(p[..., 0] - c[0], p[..., 1] - c[1]) - float(radius)


def _taubin_centered_svd(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float, float, np.ndarray, float]:
    """The Taubin problem (Eq. 28-29) in centred coordinates, solved by SVD.

    Returns ``(x, y, xm, ym, zm, v, s)``: columns/rows of the points, their means,
    the mean squared centred radius, the right singular vector of the smallest
    singular value of ``[(z - zm)/s, xc, yc]`` and the scale ``s = 2 sqrt(zm)``.
    """
    y, x = p[:, 0], p[:, 1]
    xm, ym = x.mean(), y.mean()
    xc, yc = x - xm, y - ym
    z = xc * xc + yc * yc
    zm = z.mean()
    if not zm > 0:
        raise DegenerateFitError("Taubin circle fit: all points coincide")
    s = 2.0 * math.sqrt(zm)
    _, sv, vt = np.linalg.svd(np.column_stack([(z - zm) / s, xc, yc]), full_matrices=False)
    if sv[1] <= 1e-12 * sv[0]:
        raise DegenerateFitError("Taubin circle fit: points are collinear or coincident")
    return x, y, xm, ym, zm, vt[-1], s


def taubin_circle_coefficients(points_rc: np.ndarray) -> np.ndarray:
    r"""Coefficients ``A = (a, b, c, d)`` of Eq. (26) minimising Eq. (28) subject to Eq. (29).

    ``x`` is the column and ``y`` the row coordinate (any fixed assignment gives
    the same circle).  The returned vector satisfies :math:`A^T N A = 1` (Eq. 32-33).
    """
    p = _as_points(points_rc, 3, "Taubin circle fit")
    x, y, xm, ym, zm, v, s = _taubin_centered_svd(p)
    a = v[0] / s
    b, c = v[1], v[2]
    d = -a * zm
    # back to the original frame: a((x+xm)^2... ) expanded
    B = b - 2 * a * xm
    C = c - 2 * a * ym
    D = d + a * (xm * xm + ym * ym) - b * xm - c * ym
    A = np.array([a, B, C, D])
    # normalise with N of Eq. (33) in the original frame
    zbar = np.mean(x * x + y * y)
    nrm = 4 * A[0] ** 2 * zbar + 4 * A[0] * A[1] * x.mean() + 4 * A[0] * A[2] * y.mean() + A[1] ** 2 + A[2] ** 2
    return A / math.sqrt(nrm) if nrm > 0 else A


def fit_circle_taubin(points_rc: np.ndarray) -> CircleFit:
    """Taubin circle fit, Eq. (26)-(35) of the Aerospace 2015 paper.

    Parameters
    ----------
    points_rc
        ``(n, 2)`` points ``(row, col)``, ``n >= 3``, not all collinear.

    Returns
    -------
    CircleFit

    Raises
    ------
    DegenerateFitError
        Fewer than 3 points, NaN, coincident or collinear points (a
        :class:`~jaxlimb.errors.LimbInputError`).
    """
    p = _as_points(points_rc, 3, "Taubin circle fit")
    x, y, xm, ym, zm, v, s = _taubin_centered_svd(p)
    a = v[0] / s
    if abs(a) < 1e-300 or abs(a) * math.sqrt(zm) < 1e-14 * math.hypot(v[1], v[2]):
        raise DegenerateFitError("Taubin circle fit: points are collinear (infinite radius)")
    d = -a * zm
    cx = -v[1] / (2 * a)
    cy = -v[2] / (2 * a)
    r = math.sqrt(v[1] ** 2 + v[2] ** 2 - 4 * a * d) / (2 * abs(a))
    center = (cy + ym, cx + xm)
    res = circle_residuals(p, center, r)
    return CircleFit(
        center_rc=(float(center[0]), float(center[1])),
        radius=float(r),
        rms=float(np.sqrt(np.mean(res * res))),
        max_abs=float(np.max(np.abs(res))),
        n=int(p.shape[0]),
    )


def circle_from_three(p1: np.ndarray, p2: np.ndarray, p3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circles through point triplets, vectorised.

    Parameters
    ----------
    p1, p2, p3
        ``(..., 2)`` arrays of ``(row, col)``.

    Returns
    -------
    center : ``(..., 2)`` array, NaN for collinear triplets.
    radius : ``(...)`` array, ``inf`` for collinear triplets.
    """
    p1, p2, p3 = (np.asarray(q, dtype=np.float64) for q in (p1, p2, p3))
    a = p2 - p1
    b = p3 - p1
    det = 2.0 * (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0])
    aa = (a * a).sum(-1)
    bb = (b * b).sum(-1)
    scale = np.maximum(aa, bb)
    ok = np.abs(det) > 1e-12 * np.maximum(scale, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        u0 = (b[..., 1] * aa - a[..., 1] * bb) / det
        u1 = (a[..., 0] * bb - b[..., 0] * aa) / det
    u = np.stack([u0, u1], -1)
    center = np.where(ok[..., None], p1 + u, np.nan)
    radius = np.where(ok, np.hypot(u0, u1), np.inf)
    return center, radius


# ============================================================================ ellipse
def _ellipse_params_from_conic(A, B, C, D, E, F):
    """Centre (x, y), semi-axes (a >= b), angle of the major axis from +x toward +y."""
    den = B * B - 4 * A * C
    if not den < 0:
        raise DegenerateFitError("ellipse fit: the conic is not an ellipse (B^2 - 4AC >= 0)")
    x0 = (2 * C * D - B * E) / den
    y0 = (2 * A * E - B * D) / den
    # value of the conic at the centre
    Fc = A * x0 * x0 + B * x0 * y0 + C * y0 * y0 + D * x0 + E * y0 + F
    M = np.array([[A, B / 2], [B / 2, C]])
    w, V = np.linalg.eigh(M)
    if Fc == 0 or np.any(-Fc / w <= 0):
        raise DegenerateFitError("ellipse fit: degenerate (imaginary or point) ellipse")
    axes = np.sqrt(-Fc / w)  # axis along eigenvector V[:, i]
    i_major = int(np.argmax(axes))
    vx, vy = V[:, i_major]
    ang = math.atan2(vy, vx)
    if ang <= -math.pi / 2:
        ang += math.pi
    elif ang > math.pi / 2:
        ang -= math.pi
    return float(x0), float(y0), float(axes[i_major]), float(axes[1 - i_major]), float(ang)


def ellipse_residuals(points_rc: np.ndarray, center_rc, semi_axes, angle_rad: float, iters: int = 60) -> np.ndarray:
    """Signed orthogonal (geometric) distances of points to an ellipse (positive outside), in px.

    Exact point-to-ellipse distance by Eberly's robust bisection on the
    parameter of the closest point (vectorised; ``iters`` bisection steps give
    ~1e-15 relative accuracy).
    """
    p = np.asarray(points_rc, dtype=np.float64)
    a, b = float(semi_axes[0]), float(semi_axes[1])
    if not (a > 0 and b > 0):
        raise DegenerateFitError(f"ellipse_residuals: semi_axes must be > 0, got {semi_axes!r}")
    ca, sa = math.cos(angle_rad), math.sin(angle_rad)
    dx = p[..., 1] - center_rc[1]
    dy = p[..., 0] - center_rc[0]
    u = ca * dx + sa * dy
    v = -sa * dx + ca * dy
    # work with the larger axis first
    if b > a:
        a, b = b, a
        u, v = v, u
    y0, y1 = np.abs(u), np.abs(v)
    inside = (y0 / a) ** 2 + (y1 / b) ** 2 <= 1.0
    # Eberly: find t with (a y0/(t+a^2))^2 + (b y1/(t+b^2))^2 = 1, t in [-b^2 + b y1, -b^2 + sqrt(a^2 y0^2 + b^2 y1^2)]
    z0 = np.maximum(y0 / a, 0)
    z1 = np.maximum(y1 / b, 0)
    r0 = (a / b) ** 2
    g = z0 * z0 + z1 * z1 - 1
    n0 = r0 * z0
    s0 = z1 - 1
    s1 = np.where(g < 0, 0.0, np.hypot(n0, z1) - 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for _ in range(iters):
            s = 0.5 * (s0 + s1)
            ratio0 = n0 / (s + r0)
            ratio1 = z1 / (s + 1)
            gs = ratio0 * ratio0 + ratio1 * ratio1 - 1
            s0 = np.where(gs < 0, s0, s)
            s1 = np.where(gs < 0, s, s1)
        s = 0.5 * (s0 + s1)
        x0 = r0 * y0 / (s + r0)
        x1 = y1 / (s + 1)
        dist = np.hypot(x0 - y0, x1 - y1)
    # y1 == 0 special case: closest point may be interior on the major axis
    spec = (y1 == 0)
    if np.any(spec):
        num = a * y0
        den = a * a - b * b
        xa = np.where(num < den, a * num / np.where(den > 0, den, 1.0), a)
        xa = np.minimum(xa, a)
        ya = np.where(num < den, b * np.sqrt(np.maximum(1 - (xa / a) ** 2, 0)), 0.0)
        d_spec = np.hypot(xa - y0, ya)
        dist = np.where(spec, d_spec, dist)
    return np.where(inside, -dist, dist)


def fit_ellipse_direct(points_rc: np.ndarray) -> EllipseFit:
    """Direct least-squares ellipse fit (Fitzgibbon et al. 1999; Halir & Flusser 1998).

    Points are centred and scaled before the fit (the algebraic fit is not
    translation invariant otherwise); the conic is returned in pixel coordinates.

    Raises
    ------
    DegenerateFitError
        Fewer than 5 points, NaN, or a degenerate configuration.
    """
    p = _as_points(points_rc, 5, "ellipse fit")
    y, x = p[:, 0], p[:, 1]
    mx, my = x.mean(), y.mean()
    sc = math.sqrt(np.mean((x - mx) ** 2 + (y - my) ** 2))
    if not sc > 0:
        raise DegenerateFitError("ellipse fit: all points coincide")
    xs, ys = (x - mx) / sc, (y - my) / sc
    D1 = np.column_stack([xs * xs, xs * ys, ys * ys])
    D2 = np.column_stack([xs, ys, np.ones_like(xs)])
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    try:
        T = -np.linalg.solve(S3, S2.T)
    except np.linalg.LinAlgError:
        raise DegenerateFitError("ellipse fit: singular scatter matrix (collinear points)") from None
    Mm = S1 + S2 @ T
    Cinv = np.array([[0, 0, 0.5], [0, -1, 0], [0.5, 0, 0]])
    Mm = Cinv @ Mm
    w, V = np.linalg.eig(Mm)
    V = np.real(V)
    cond = 4 * V[0] * V[2] - V[1] ** 2
    idx = np.where(cond > 0)[0]
    if idx.size == 0:
        raise DegenerateFitError("ellipse fit: no elliptical solution")
    a1 = V[:, idx[0]]
    a2 = T @ a1
    A, B, C = a1
    D, E, F = a2
    # undo scaling: x = (X - mx)/sc
    A2, B2, C2 = A / sc**2, B / sc**2, C / sc**2
    D2_ = D / sc - 2 * A2 * mx - B2 * my
    E2 = E / sc - 2 * C2 * my - B2 * mx
    F2 = (A2 * mx * mx + B2 * mx * my + C2 * my * my) - (D / sc) * mx - (E / sc) * my + F
    nrm = math.sqrt(A2 * A2 + B2 * B2 + C2 * C2 + D2_ * D2_ + E2 * E2 + F2 * F2)
    coef = tuple(float(c / nrm) for c in (A2, B2, C2, D2_, E2, F2))
    x0, y0, sa, sb, ang = _ellipse_params_from_conic(*coef)
    res = ellipse_residuals(p, (y0, x0), (sa, sb), ang)
    return EllipseFit(
        center_rc=(y0, x0),
        semi_axes=(sa, sb),
        angle_rad=ang,
        conic=coef,  # type: ignore[arg-type]
        rms=float(np.sqrt(np.mean(res * res))),
        max_abs=float(np.max(np.abs(res))),
        n=int(p.shape[0]),
    )


__all__ = [
    "CircleFit",
    "DegenerateFitError",
    "EllipseFit",
    "circle_from_three",
    "circle_residuals",
    "ellipse_residuals",
    "fit_circle_taubin",
    "fit_ellipse_direct",
    "taubin_circle_coefficients",
]
