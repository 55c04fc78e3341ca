r"""The image of a sphere parametrised by its ellipse centre and radial semi-axis, and its inverse.

Off the optical axis a sphere's limb is an ellipse elongated radially whose centre is *not*
the image of the body centre (:func:`jaxlimb.geometry.camera.sphere_image_ellipse`).  With
``theta`` the angle of the body centre from the boresight, ``alpha = asin(R/D)`` and
``den = cos^2(theta) - sin^2(alpha)`` (pinhole, focal length ``f`` px):

.. math::
    \rho_0 = f\,\frac{\sin\theta\cos\theta}{den}, \qquad
    a = f\,\frac{\sin\alpha\cos\alpha}{den}, \qquad
    b = f\,\frac{\sin\alpha}{\sqrt{den}}, \qquad
    \rho_{body} = f\tan\theta

(``rho_0`` the distance of the ellipse centre from the principal point, ``a`` radial,
``b`` tangential, ``rho_body`` the distance of the image of the centre).  Three numbers --
the ellipse centre (2) and ``a`` (1) -- therefore fix the whole image: the axis ratio
``b/a = sqrt(den)/cos(alpha)``, the orientation (``a`` along the radial direction ``phi``),
the body-centre image and ``alpha`` (hence the range ``R/sin(alpha)``).  This module inverts
that map exactly: for a trial ``alpha`` the centre equation gives ``t = tan(theta)`` in
closed form (positive root of ``k s^2 t^2 + t - k (1 - s^2) = 0``, ``k = rho_0/f``,
``s = sin(alpha)``; the same root as :func:`jaxlimb.geometry.navigation.sphere_from_ellipse`),
and a 1-D Newton iteration on ``alpha`` matches ``a``.  ``alpha`` is unique because
``a(alpha)`` increases monotonically at fixed ellipse centre.

It is what makes the body-centre correction of :func:`jaxlimb.pipeline.locate` exact: the
elliptical sigmoid is fitted with ``rho = b/a`` and ``theta = -phi`` held at the values of
this map at the current estimate, iterated once, and the fitted ``(centre, a)`` are mapped
to the body centre here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import GeometryError
from ..numerics import numerical_jacobian


@dataclass(frozen=True)
class SphereImage:
    """The image of a sphere (pinhole, ideal pixel coordinates).

    Attributes
    ----------
    ellipse_center_rc : the limb ellipse centre ``(row, col)``.
    a, b : radial (semi-major) and tangential semi-axes (px).
    rho : ``b / a`` (<= 1).
    angle_rad : direction of ``a`` in the convention of :func:`jaxlimb.models.ellipse_coords`
        (from ``+col`` toward ``-row``), i.e. ``-phi`` reduced to ``[0, pi)``.
    theta_rad : angle of the body centre from the boresight.
    phi_rad : image direction of the body centre from the principal point, ``atan2(d_row, d_col)``.
    alpha_rad : angular radius ``asin(R/D)``.
    body_center_rc : the image of the body centre (ideal pixels).
    los : unit line of sight to the body centre (camera frame).
    """

    ellipse_center_rc: tuple[float, float]
    a: float
    b: float
    rho: float
    angle_rad: float
    theta_rad: float
    phi_rad: float
    alpha_rad: float
    body_center_rc: tuple[float, float]
    los: tuple[float, float, float]

    @property
    def radius_equivalent_px(self) -> float:
        """``f tan(alpha) = b^2 / a``: the radius the sphere would have on the boresight."""
        return self.b * self.b / self.a


def _tan_theta(k: float, s: float) -> float:
    s2 = s * s
    return 2.0 * k * (1.0 - s2) / (1.0 + math.sqrt(1.0 + 4.0 * k * k * s2 * (1.0 - s2)))


def _a_of_alpha(k: float, alpha: float) -> float:
    """``a / f`` of the sphere whose ellipse centre is at ``k f`` for angular radius ``alpha``."""
    s = math.sin(alpha)
    th = math.atan(_tan_theta(k, s))
    den = math.cos(th) ** 2 - s * s
    if den <= 0:
        return math.inf
    return s * math.cos(alpha) / den


def _alpha_of_a(k: float, target: float, tol: float, max_iter: int, what: str) -> float:
    """The sphere's angular radius whose image ellipse has the radial semi-axis ``target`` (focal units) at
    ``k = rho_c / f``: Newton with a central-difference derivative (the map is smooth and increasing); ``what``
    describes the ellipse in the :class:`GeometryError` of no solution."""
    alpha = math.atan(target)
    for _ in range(max_iter):
        val = _a_of_alpha(k, alpha)
        h = 1e-6 * alpha
        d = (_a_of_alpha(k, alpha + h) - _a_of_alpha(k, alpha - h)) / (2 * h)
        if not (math.isfinite(val) and math.isfinite(d) and d > 0):
            raise GeometryError(f"no sphere has an image ellipse {what}")
        step = (val - target) / d
        alpha_new = alpha - step
        if alpha_new <= 0:
            alpha_new = 0.5 * alpha
        alpha = alpha_new
        if abs(step) <= tol * max(alpha, 1e-300):
            break
    return alpha


def sphere_from_ellipse_center(focal_px: float, principal_point_rc, ellipse_center_rc, a_px: float,
                               tol: float = 1e-15, max_iter: int = 60) -> SphereImage:
    """Invert the sphere-image map: ellipse centre and radial semi-axis -> the sphere's image.

    Parameters
    ----------
    focal_px : focal length (px).
    principal_point_rc : principal point ``(row, col)``.
    ellipse_center_rc : the limb ellipse centre ``(row, col)`` (ideal, undistorted pixels).
    a_px : radial (semi-major) semi-axis (px, > 0).

    Raises
    ------
    GeometryError
        Non-finite input, ``a_px <= 0`` or no sphere with this image (limb beyond 90 deg).
    """
    f = float(focal_px)
    r0, c0 = (float(v) for v in principal_point_rc)
    er, ec = (float(v) for v in ellipse_center_rc)
    a = float(a_px)
    if not all(math.isfinite(v) for v in (f, r0, c0, er, ec, a)) or a <= 0 or f <= 0:
        raise GeometryError(
            f"sphere image needs finite centre and a_px > 0, got centre ({er!r}, {ec!r}), a_px = {a!r}"
        )
    dr, dc = er - r0, ec - c0
    rho_c = math.hypot(dr, dc)
    phi = math.atan2(dr, dc) if rho_c > 0 else 0.0
    k = rho_c / f
    target = a / f
    alpha = _alpha_of_a(k, target, tol, max_iter, f"centred {rho_c:.6g} px off-axis with a = {a:.6g} px")
    s = math.sin(alpha)
    t = _tan_theta(k, s)
    th = math.atan(t)
    den = math.cos(th) ** 2 - s * s
    if den <= 0 or th + alpha >= math.pi / 2:
        raise GeometryError("the sphere's limb reaches the image plane at infinity (not an ellipse)")
    a_fit = f * s * math.cos(alpha) / den
    b_fit = f * s / math.sqrt(den)
    rho_b = f * t
    los = (math.sin(th) * math.cos(phi), math.sin(th) * math.sin(phi), math.cos(th))
    return SphereImage(
        ellipse_center_rc=(er, ec),
        a=a_fit,
        b=b_fit,
        rho=b_fit / a_fit,
        angle_rad=(-phi) % math.pi,
        theta_rad=th,
        phi_rad=phi,
        alpha_rad=alpha,
        body_center_rc=(r0 + rho_b * math.sin(phi), c0 + rho_b * math.cos(phi)),
        los=los,
    )


def sphere_jacobian(focal_px: float, principal_point_rc, ellipse_center_rc, a_px: float) -> np.ndarray:
    """``d(body_row, body_col, f tan(alpha)) / d(ellipse_row, ellipse_col, a)`` (3x3, central differences).

    Used to propagate the fit covariance of the elliptical sigmoid's ``(r0, c0, a)`` to the
    body centre and the equivalent radius.  Step 1e-4 px: the map is smooth on the px scale,
    so the truncation error (~1e-8 relative) is far below the statistical errors.
    """
    def out(x: np.ndarray) -> np.ndarray:
        s = sphere_from_ellipse_center(focal_px, principal_point_rc, (x[0], x[1]), x[2])
        return np.array([s.body_center_rc[0], s.body_center_rc[1], s.radius_equivalent_px])

    x0 = np.array([float(ellipse_center_rc[0]), float(ellipse_center_rc[1]), float(a_px)])
    return numerical_jacobian(out, x0, 1e-4)


def _mean_ab(k: float, alpha: float) -> float:
    """``(a + b) / (2 f)`` of the sphere whose ellipse centre is at ``k f`` for angular radius ``alpha``."""
    s = math.sin(alpha)
    th = math.atan(_tan_theta(k, s))
    den = math.cos(th) ** 2 - s * s
    return 0.5 * (s * math.cos(alpha) / den + s / math.sqrt(den))


def image_mean_radius(focal_px: float, principal_point_rc, center_rc, radius_equivalent_px: float) -> float:
    """The mean radius ``(a + b) / 2`` (px) of the image ellipse centred at ``center_rc`` of the sphere whose
    on-axis-equivalent radius ``f tan(alpha)`` is ``radius_equivalent_px``: the inverse of
    :func:`sphere_from_circle_fit`'s radius map.

    Parameters
    ----------
    focal_px : float
        Focal length (px).
    principal_point_rc : tuple of float
        Principal point ``(row, col)`` (px).
    center_rc : tuple of float
        Ellipse centre ``(row, col)`` (ideal px).
    radius_equivalent_px : float
        ``f tan(alpha)`` (px).

    Returns
    -------
    float
        The ellipse's mean radius (px).
    """
    f = float(focal_px)
    r0, c0 = (float(v) for v in principal_point_rc)
    k = math.hypot(float(center_rc[0]) - r0, float(center_rc[1]) - c0) / f
    return f * _mean_ab(k, math.atan(float(radius_equivalent_px) / f))


def sphere_from_circle_fit(focal_px: float, principal_point_rc, center_rc, mean_radius: float,
                           tol: float = 1e-14, max_iter: int = 60) -> SphereImage:
    """The sphere whose image ellipse has centre ``center_rc`` and mean radius ``(a + b)/2 = mean_radius``.

    1-D Newton on ``alpha`` (the centre equation gives ``theta`` in closed form), then
    :func:`sphere_from_ellipse_center` with the matching ``a``.
    """
    f = float(focal_px)
    r0, c0 = (float(v) for v in principal_point_rc)
    k = math.hypot(float(center_rc[0]) - r0, float(center_rc[1]) - c0) / f

    target = float(mean_radius) / f
    alpha = math.atan(target)
    for _ in range(max_iter):
        h = 1e-6 * alpha
        dm = (_mean_ab(k, alpha + h) - _mean_ab(k, alpha - h)) / (2 * h)
        if not (math.isfinite(dm) and dm > 0):
            raise GeometryError(f"no sphere has an image of mean radius {mean_radius!r} px there")
        step = (_mean_ab(k, alpha) - target) / dm
        alpha -= step
        if abs(step) <= tol * alpha:
            break
    a = f * _a_of_alpha(k, alpha)
    return sphere_from_ellipse_center(f, principal_point_rc, center_rc, a)


__all__ = ["SphereImage", "image_mean_radius", "sphere_from_circle_fit", "sphere_from_ellipse_center",
           "sphere_jacobian"]
