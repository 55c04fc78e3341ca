"""The pipeline's side of the physical limb profile: the accepted range of the fitted ``L`` and the
sphere whose image has a given centre and mean radius.

The model itself (:data:`LIMB_PROFILE`, :func:`limb_profile_intensity`, its Jacobian) lives in
:mod:`jaxlimb.models.lunar_lambert`; its names are re-exported here for older imports.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import GeometryError
from ..models.lunar_lambert import (  # noqa: F401  (the model moved to jaxlimb.models; re-exported)
    LIMB_PROFILE as LIMB_PROFILE,
    PHYSICAL_L as PHYSICAL_L,
    PROFILE_FIXED as PROFILE_FIXED,
    LimbProfileParams as LimbProfileParams,
    limb_profile_intensity as limb_profile_intensity,
    lunar_lambert_weight as lunar_lambert_weight,
)
from .sphere import SphereImage, _a_of_alpha, _tan_theta, sphere_from_ellipse_center


def l_band(fit) -> tuple[float, float]:
    """The accepted range of ``L`` for ``fit`` (a :class:`~jaxlimb.fitting.LimbFit` of :data:`LIMB_PROFILE`):
    :data:`PHYSICAL_L` widened by 3 sigma of ``L`` when ``L`` was estimated."""
    if "L" not in fit.free:
        return (-math.inf, math.inf)
    i = list(fit.free).index("L")
    s = float(np.sqrt(max(float(np.asarray(fit.covariance)[i, i]), 0.0)))
    return (PHYSICAL_L[0] - 3.0 * s, PHYSICAL_L[1] + 3.0 * s)


def sphere_from_circle_fit(focal_px: float, principal_point_rc, center_rc, mean_radius: float,
                           tol: float = 1e-14, max_iter: int = 60) -> SphereImage:
    """The sphere whose image ellipse has centre ``center_rc`` and mean radius ``(a + b)/2 = mean_radius``.

    1-D Newton on ``alpha`` (the centre equation gives ``theta`` in closed form), then
    :func:`~jaxlimb.pipeline.sphere.sphere_from_ellipse_center` with the matching ``a``.
    """
    f = float(focal_px)
    r0, c0 = (float(v) for v in principal_point_rc)
    k = math.hypot(float(center_rc[0]) - r0, float(center_rc[1]) - c0) / f

    def mean_ab(alpha: float) -> float:
        s = math.sin(alpha)
        th = math.atan(_tan_theta(k, s))
        den = math.cos(th) ** 2 - s * s
        return 0.5 * (s * math.cos(alpha) / den + s / math.sqrt(den))

    target = float(mean_radius) / f
    alpha = math.atan(target)
    for _ in range(max_iter):
        h = 1e-6 * alpha
        dm = (mean_ab(alpha + h) - mean_ab(alpha - h)) / (2 * h)
        if not (math.isfinite(dm) and dm > 0):
            raise GeometryError(f"no sphere has an image of mean radius {mean_radius!r} px there")
        step = (mean_ab(alpha) - target) / dm
        alpha -= step
        if abs(step) <= tol * alpha:
            break
    a = f * _a_of_alpha(k, alpha)
    return sphere_from_ellipse_center(f, principal_point_rc, center_rc, a)


__all__ = [
    "LIMB_PROFILE",
    "LimbProfileParams",
    "PHYSICAL_L",
    "PROFILE_FIXED",
    "l_band",
    "limb_profile_intensity",
    "lunar_lambert_weight",
    "sphere_from_circle_fit",
]
