"""Algebraic conic fits (Taubin circle, direct ellipse) and RANSAC with index rotation.

See :mod:`jaxlimb.conics.taubin` (Eq. 26-35 of the Aerospace 2015 paper) and
:mod:`jaxlimb.conics.ransac` (§4.3).  Points are ``(n, 2)`` arrays of ``(row, col)``.
"""

from .ransac import (
    RansacOptions as RansacOptions,
    RansacResult as RansacResult,
    pyramid_triplets as pyramid_triplets,
    ransac_circle as ransac_circle,
)
from .taubin import (
    CircleFit as CircleFit,
    DegenerateFitError as DegenerateFitError,
    EllipseFit as EllipseFit,
    circle_from_three as circle_from_three,
    circle_residuals as circle_residuals,
    ellipse_residuals as ellipse_residuals,
    fit_circle_taubin as fit_circle_taubin,
    fit_ellipse_direct as fit_ellipse_direct,
    taubin_circle_coefficients as taubin_circle_coefficients,
)

__all__ = [
    "CircleFit",
    "DegenerateFitError",
    "EllipseFit",
    "RansacOptions",
    "RansacResult",
    "circle_from_three",
    "circle_residuals",
    "ellipse_residuals",
    "fit_circle_taubin",
    "fit_ellipse_direct",
    "pyramid_triplets",
    "ransac_circle",
    "taubin_circle_coefficients",
]
