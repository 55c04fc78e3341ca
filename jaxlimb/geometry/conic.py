r"""Image conics and ellipses: the pixel conic of an ellipse and back, points on it, the first-order signed
distance to it and the largest displacement between two of them.

Homogeneous pixel order of conics
---------------------------------
Every 3x3 pixel conic ``C`` returned here acts on **``h = [col, row, 1]``**
(the order produced by :attr:`jaxlimb.geometry.camera.Camera.K`), i.e. a pixel
``(row, col)`` lies on the curve when ``h^T C h = 0``.  Conics are scaled to unit
Frobenius norm and signed so that ``h^T C h < 0`` **inside** the ellipse (on the
body's disk) and ``> 0`` outside.  Use :func:`conic_eval` to evaluate a conic at
``(row, col)`` points without worrying about the order.

Ellipse angle convention
------------------------
``angle_rad`` (``theta``) is the direction of the **semi-major** axis, measured
from the ``+col`` axis turning toward ``-row`` (i.e. counter-clockwise on the
image as displayed, row pointing down): the major axis points along
``(d_row, d_col) = (-sin theta, cos theta)``, and ``theta`` is reduced to
``[0, pi)``.  This is the same convention as the ``theta`` of
:class:`jaxlimb.models.EllipseParams` (``ellipse_coords``) with ``a`` the
semi-major axis, so a truth ellipse can seed an elliptical-sigmoid fit directly
(``rho = b/a``).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import GeometryError


def conic_eval(C: np.ndarray, rc: np.ndarray) -> np.ndarray:
    """Evaluate a pixel conic (order ``[col, row, 1]``) at points ``rc`` ``(..., 2)`` given as ``(row, col)``."""
    rc = np.asarray(rc, dtype=float)
    c, r = rc[..., 1], rc[..., 0]
    return (
        C[0, 0] * c * c
        + 2 * C[0, 1] * c * r
        + C[1, 1] * r * r
        + 2 * C[0, 2] * c
        + 2 * C[1, 2] * r
        + C[2, 2]
    )


def normalise_conic(C: np.ndarray, inside_rc: tuple[float, float] | None = None) -> np.ndarray:
    """``C`` symmetric, of unit Frobenius norm, and negative at ``inside_rc`` (when given)."""
    C = 0.5 * (C + C.T)
    C = C / np.linalg.norm(C)
    if inside_rc is not None and conic_eval(C, np.array(inside_rc)) > 0:
        C = -C
    return C


def conic_to_ellipse(C: object) -> tuple[tuple[float, float], tuple[float, float], float]:
    r"""Ellipse parameters of a pixel conic (order ``[col, row, 1]``).

    Returns
    -------
    center_rc, semi_axes_px, angle_rad
        Centre ``(row, col)``; semi-axes ``(a, b)`` with ``a >= b``; ``angle_rad`` in
        ``[0, pi)``: the semi-major axis points along ``(d_row, d_col) = (-sin, cos)``
        of it (counter-clockwise from ``+col`` as displayed; module docstring).

    Derivation.  Write :math:`C = [[S, g], [g^T, F]]` with the 2x2 block
    :math:`S` on :math:`u = (c, r)`.  The centre solves :math:`S u_0 = -g`; then
    :math:`(u-u_0)^T S (u-u_0) = -F_0` with :math:`F_0 = F + g^T u_0`.  With
    :math:`S = \sum_i \ell_i e_i e_i^T` the semi-axes are :math:`\sqrt{-F_0/\ell_i}`
    along :math:`e_i` (an ellipse needs :math:`\ell_1\ell_2 > 0` and
    :math:`F_0\ell_i < 0`).

    Raises
    ------
    GeometryError
        The conic is not a real, non-degenerate ellipse.
    """
    C = np.asarray(C, dtype=float)
    if C.shape != (3, 3) or not np.all(np.isfinite(C)):
        raise GeometryError(f"conic `C` must be a finite 3x3 matrix, got shape {C.shape}")
    C = 0.5 * (C + C.T)
    S = C[:2, :2]
    g = C[:2, 2]
    detS = float(np.linalg.det(S))
    scale = float(np.max(np.abs(S)))
    if not (scale > 0 and detS > 1e-14 * scale * scale):
        raise GeometryError(f"conic is not an ellipse (det of the quadratic part = {detS:.3g} <= 0)")
    u0 = np.linalg.solve(S, -g)
    F0 = float(C[2, 2] + g @ u0)
    ell, E = np.linalg.eigh(S)
    if not (F0 * ell[0] < 0 and F0 * ell[1] < 0):
        raise GeometryError("conic is an imaginary or degenerate ellipse (no real points)")
    ax = np.sqrt(-F0 / ell)  # ell ascending in |.| if positive; handle both signs below
    i_major = int(np.argmax(ax))
    a, b = float(ax[i_major]), float(ax[1 - i_major])
    dc, dr = E[0, i_major], E[1, i_major]
    theta = math.atan2(-dr, dc) % math.pi
    if theta >= math.pi:  # guard rounding
        theta = 0.0
    return (float(u0[1]), float(u0[0])), (a, b), theta


def ellipse_to_conic(center_rc: object, semi_axes_px: object, angle_rad: float) -> np.ndarray:
    r"""Pixel conic (order ``[col, row, 1]``, negative inside, unit Frobenius norm) of an ellipse.

    With :math:`x = (c-c_0)\cos\theta - (r-r_0)\sin\theta` and
    :math:`y = -(r-r_0)\cos\theta - (c-c_0)\sin\theta` (the frame of
    :func:`jaxlimb.models.sigmoid.ellipse_coords`), the ellipse is
    :math:`x^2/a^2 + y^2/b^2 - 1 = 0`.
    """
    r0, c0 = (float(v) for v in np.asarray(center_rc, dtype=float))
    a, b = (float(v) for v in np.asarray(semi_axes_px, dtype=float))
    if not (a > 0 and b > 0 and math.isfinite(a) and math.isfinite(b)):
        raise GeometryError(f"`semi_axes_px` must be finite and > 0, got {(a, b)}")
    ct, st = math.cos(angle_rad), math.sin(angle_rad)
    # x = [ct, -st] . (c - c0, r - r0),  y = [-st, -ct] . (c - c0, r - r0)
    ux = np.array([ct, -st])
    uy = np.array([-st, -ct])
    S = np.outer(ux, ux) / a**2 + np.outer(uy, uy) / b**2
    u0 = np.array([c0, r0])
    C = np.zeros((3, 3))
    C[:2, :2] = S
    C[:2, 2] = C[2, :2] = -S @ u0
    C[2, 2] = u0 @ S @ u0 - 1.0
    return C / np.linalg.norm(C)


def ellipse_points(
    center_rc: object, semi_axes_px: object, angle_rad: float, phi: np.ndarray
) -> np.ndarray:
    """Points ``(row, col)`` ``(n, 2)`` at eccentric anomalies ``phi`` (same frame as :func:`ellipse_to_conic`)."""
    r0, c0 = (float(v) for v in np.asarray(center_rc, dtype=float))
    a, b = (float(v) for v in np.asarray(semi_axes_px, dtype=float))
    phi = np.asarray(phi, dtype=float)
    x, y = a * np.cos(phi), b * np.sin(phi)
    ct, st = math.cos(angle_rad), math.sin(angle_rad)
    return np.stack([r0 - x * st - y * ct, c0 + x * ct - y * st], axis=-1)


def ellipse_signed_distance(pts: np.ndarray, ell: tuple) -> np.ndarray:
    """Signed first-order distance (px) of pixels ``(..., 2)`` to the ellipse (negative inside):
    ``F / |grad F|`` with ``F = x^2/a^2 + y^2/b^2 - 1`` in the ellipse frame of
    :func:`jaxlimb.models.ellipse_coords` (Eq. 19), computed in float64 NumPy: the JAX transform runs in float32,
    whose 1e-4 px resolution at a 2000 px centre swallowed the finite-difference steps of the fits that call this
    (a fitted ellipse centre never moved from its start)."""
    (r0, c0), (a, b), th = ell
    p = np.asarray(pts, float)
    dr, dc = p[..., 0] - float(r0), p[..., 1] - float(c0)
    ct, st = math.cos(float(th)), math.sin(float(th))
    x, y = dc * ct - dr * st, -dr * ct - dc * st
    F = x * x / (a * a) + y * y / (b * b) - 1.0
    g = 2.0 * np.hypot(x / (a * a), y / (b * b))
    return F / np.maximum(g, 1e-300)


def ellipse_change(e1: tuple, e2: tuple) -> float:
    """Largest displacement (px) between two ellipses, sampled at 64 points."""
    phi = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    # compare the two curves by the distance of e1's points to e2 (first order)
    p1 = ellipse_points(e1[0], e1[1], e1[2], phi)
    return float(np.max(np.abs(ellipse_signed_distance(p1, e2))))


__all__ = ["conic_eval", "conic_to_ellipse", "ellipse_change", "ellipse_points", "ellipse_signed_distance", "ellipse_to_conic",
           "normalise_conic"]
