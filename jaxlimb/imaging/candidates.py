"""The common result of the two front ends: :class:`LimbCandidates`.

Both front ends (:func:`jaxlimb.imaging.gradient.gradient_front_end` and
:func:`jaxlimb.imaging.scanline.scanline_front_end`) return a
:class:`LimbCandidates`: the limb points they kept, the initial circle (Taubin,
Eq. 26-35 of the Aerospace 2015 paper) and the direction of the lit limb.

How the next stage uses it (pixel selection for the circular-sigmoid fit,
Aerospace 2015 §5 / illuminated-ellipsoid paper §VI): take the pixels whose
distance ``rho`` from ``center_rc`` satisfies ``|rho - radius| <= dr`` (with
``dr`` a few times the blur width plus ``residual_rms``), and -- when
``lit_direction`` is not ``None`` -- whose polar angle from ``center_rc``
lies within ``lit_halfangle`` of ``lit_direction``.  When ``lit_direction`` is
``None`` (full disk, or unknown) the whole annulus inside the image is lit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class LimbCandidates:
    """Limb points and initial circle from a front end.

    Attributes
    ----------
    points_rc
        ``(m, 2)`` float array of limb points ``(row, col)`` in full-image pixel
        coordinates (the inliers used for the circle).
    center_rc
        Initial circle centre ``(row, col)`` (px); may lie outside the image.
    radius
        Initial circle radius (px).
    residual_rms
        RMS geometric residual of ``points_rc`` about the circle (px).
    lit_direction
        Unit 2-vector ``(d_row, d_col)`` from the centre toward the middle of the
        lit limb, or ``None`` when the whole limb is lit / the side is unknown.
    lit_halfangle
        Half-width (rad) of the lit arc about ``lit_direction`` covered by
        ``points_rc`` (``pi`` for a full disk).
    front_end
        ``"gradient"`` or ``"scanline"``.
    info
        Diagnostics: counts after each stage, the settings used (N, box size,
        RANSAC distance/tests), timings, the other candidate set of the scan-line
        front end, the region of interest, the cropping detection, ...
    """

    points_rc: np.ndarray = field(repr=False)
    center_rc: tuple[float, float]
    radius: float
    residual_rms: float
    lit_direction: tuple[float, float] | None
    lit_halfangle: float
    front_end: str
    info: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def center(self) -> np.ndarray:
        """Centre as an array ``[row, col]``."""
        return np.array(self.center_rc, dtype=float)

    @property
    def n_points(self) -> int:
        """Number of limb points ``m``."""
        return int(self.points_rc.shape[0])

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays, no diagnostics)."""
        return {
            "front_end": self.front_end,
            "center_rc": [float(self.center_rc[0]), float(self.center_rc[1])],
            "radius_px": float(self.radius),
            "residual_rms_px": float(self.residual_rms),
            "n_points": self.n_points,
            "lit_direction": None if self.lit_direction is None else [float(x) for x in self.lit_direction],
            "lit_halfangle_rad": float(self.lit_halfangle),
        }


def lit_arc(points_rc: np.ndarray, center_rc, direction: tuple[float, float] | None = None):
    """Direction (unit ``(d_row, d_col)``) and half-angle of the arc covered by ``points_rc``.

    The mean of the unit vectors from the centre to the points gives the arc's
    middle; when its length is below 0.15 (points spread all around, a full
    disk) the direction is ``None`` and the half-angle ``pi``.  A given
    ``direction`` (e.g. the projected Sun direction) is used instead of the
    mean when provided.  The half-angle is the largest angle between the
    direction and a point.
    """
    p = np.asarray(points_rc, float)
    c = np.asarray(center_rc, float)
    v = p - c
    nv = np.linalg.norm(v, axis=1)
    good = nv > 0
    if not good.any():
        return None, float(np.pi)
    u = v[good] / nv[good, None]
    if direction is None:
        m = u.mean(0)
        if np.linalg.norm(m) < 0.15:
            return None, float(np.pi)
        d = m / np.linalg.norm(m)
    else:
        d = np.asarray(direction, float)
        d = d / np.linalg.norm(d)
    ang = np.arccos(np.clip(u @ d, -1.0, 1.0))
    return (float(d[0]), float(d[1])), float(ang.max())


__all__ = ["LimbCandidates", "lit_arc"]
