r"""Pinhole rays, ray--ellipsoid intersection and the exact truth of the independent renderer.

Written without :mod:`jaxlimb.geometry` or :mod:`jaxlimb.render` so that a shared mistake
cannot hide in both the estimator and its validation.  Conventions (docs/design.md): pixel
``(row, col)``, ``(0, 0)`` the centre of the top-left pixel; camera frame ``+z`` boresight,
``+x`` toward ``+col``, ``+y`` toward ``+row``; ``R_body_to_camera`` maps body-fixed vectors
to the camera frame; the Sun direction points from the body toward the Sun.

Ray casting.  The ray through image point ``(row, col)`` has camera direction
:math:`d = ((c - c_c)/f,\ (r - r_c)/f,\ 1)`.  In the body frame scaled by the radii
(:math:`\tilde x = R^\top x / (a, b, c)`) the ellipsoid is the unit sphere, the camera sits at
:math:`O = -R^\top q / (a, b, c)` and the ray is :math:`O + t D`, :math:`D = R^\top d / (a,b,c)`.
It hits the body iff the distance of its closest approach to the origin,
:math:`\rho = \sqrt{|O|^2 - (O\cdot D)^2/|D|^2}`, is below 1; the near intersection is
:math:`t = (-O\cdot D - \sqrt{(O\cdot D)^2 - |D|^2(|O|^2-1)})/|D|^2`.

Truth.  The limb is the cone of rays tangent to the ellipsoid: with
:math:`A = R\,\mathrm{diag}(a^{-2}, b^{-2}, c^{-2})R^\top` and body centre :math:`q`,
:math:`d^\top M d = 0`, :math:`M = (Aq)(Aq)^\top - (q^\top A q - 1)A` (for a unit sphere:
:math:`(q\cdot d)^2 = (|q|^2 - 1)|d|^2`, the tangent cone).  Its image in homogeneous pixel
coordinates :math:`h = (c, r, 1)` is the conic :math:`K^{-\top} M K^{-1}`, from which the
ellipse centre, semi-axes and orientation follow; the image of the body centre is the
projection of :math:`q`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Pinhole:
    """An ideal pinhole camera: focal length in pixels, frame size, principal point ``(row, col)``."""

    focal_px: float
    rows: int
    cols: int
    principal_point_rc: tuple[float, float]

    @classmethod
    def from_camera(cls, camera) -> Pinhole:
        """From any object with ``focal_length_mm, pixel_pitch_mm, rows, cols, principal_point_rc``."""
        f = float(camera.focal_length_mm) / float(camera.pixel_pitch_mm)
        pp = camera.principal_point_rc
        return cls(f, int(camera.rows), int(camera.cols), (float(pp[0]), float(pp[1])))

    def directions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Camera-frame (unnormalised, ``z = 1``) ray directions through image points ``(..., 3)``."""
        r0, c0 = self.principal_point_rc
        x = (np.asarray(cols, float) - c0) / self.focal_px
        y = (np.asarray(rows, float) - r0) / self.focal_px
        return np.stack([x, y, np.ones_like(x)], axis=-1)

    def project(self, v) -> tuple[float, float]:
        """Image point ``(row, col)`` of the camera-frame point ``v`` (``z > 0``)."""
        v = np.asarray(v, float)
        r0, c0 = self.principal_point_rc
        return (r0 + self.focal_px * v[1] / v[2], c0 + self.focal_px * v[0] / v[2])

    def los(self, rc) -> np.ndarray:
        """Unit line of sight through image point ``rc``."""
        d = self.directions(np.asarray(rc[0]), np.asarray(rc[1]))
        return d / np.linalg.norm(d)


@dataclass(frozen=True, eq=False)
class Body:
    """A sunlit triaxial ellipsoid: radii (km), centre in the camera frame (km), attitude, Sun."""

    radii: tuple[float, float, float]
    center_cam: np.ndarray
    R_body_to_camera: np.ndarray
    sun_dir_cam: np.ndarray

    @property
    def range_km(self) -> float:
        return float(np.linalg.norm(self.center_cam))

    @property
    def observer_scaled(self) -> np.ndarray:
        """Camera position in the scaled body frame (the body is the unit sphere there)."""
        return -(self.R_body_to_camera.T @ np.asarray(self.center_cam, float)) / np.asarray(self.radii)


@dataclass(frozen=True)
class Hits:
    """Per-ray intersection data: ``rho``, ``hit``, ``d_body`` over all rays; the surface
    quantities over the rays that hit (``x_body[k]`` is the ``k``-th hit)."""

    rho: np.ndarray  # closest approach in the scaled frame (< 1: the ray hits)
    hit: np.ndarray
    d_body: np.ndarray  # unit ray directions, body frame
    x_body: np.ndarray  # surface points, body frame, km
    normal: np.ndarray  # outward unit normals, body frame
    mu: np.ndarray  # emission cosines
    mu0: np.ndarray  # incidence cosines
    cos_g: np.ndarray  # cosines of the phase angle at the points


def _scaled(body: Body, d_cam: np.ndarray):
    d = d_cam / np.sqrt(np.einsum("ij,ij->i", d_cam, d_cam))[:, None]
    d_b = d @ body.R_body_to_camera
    r = np.asarray(body.radii, float)
    O = body.observer_scaled
    D = d_b / r
    DD = np.einsum("ij,ij->i", D, D)
    OD = D @ O
    OO = float(O @ O)
    return d_b, DD, OD, OO


def closest_approach(body: Body, d_cam: np.ndarray) -> np.ndarray:
    """``rho`` (module docstring) of camera rays ``(n, 3)``."""
    _, DD, OD, OO = _scaled(body, d_cam)
    return np.sqrt(np.maximum(OO - OD * OD / DD, 0.0))


def cast(body: Body, d_cam: np.ndarray) -> Hits:
    """Intersect camera rays ``(n, 3)`` (any length) with ``body`` (module docstring)."""
    d_b, DD, OD, OO = _scaled(body, d_cam)
    rho = np.sqrt(np.maximum(OO - OD * OD / DD, 0.0))
    hit = rho < 1.0
    r = np.asarray(body.radii, float)
    DDh, ODh, db = DD[hit], OD[hit], d_b[hit]
    t = (-ODh - np.sqrt(np.maximum(ODh * ODh - DDh * (OO - 1.0), 0.0))) / DDh
    x = body.observer_scaled * r + t[:, None] * db
    n = x / (r * r)
    n /= np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    s_b = body.R_body_to_camera.T @ np.asarray(body.sun_dir_cam, float)
    return Hits(rho, hit, d_b, x, n, -np.einsum("ij,ij->i", n, db), n @ s_b, -(db @ s_b))


@dataclass(frozen=True)
class LimbTruth:
    """The exact answer for one rendered body."""

    body_center_rc: tuple[float, float]
    ellipse_center_rc: tuple[float, float]
    semi_axes_px: tuple[float, float]
    angle_rad: float  # major axis, from +col toward -row, in [0, pi)
    range_km: float
    apparent_radius_px: float  # f tan(asin(R_mean / range)) (the sphere's on-axis-equivalent radius)

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def limb_conic(body: Body, pin: Pinhole) -> np.ndarray:
    """The 3x3 image conic of the limb in homogeneous ``(col, row, 1)`` (module docstring)."""
    R = body.R_body_to_camera
    A = R @ np.diag(1.0 / np.asarray(body.radii, float) ** 2) @ R.T
    q = np.asarray(body.center_cam, float)
    Aq = A @ q
    M = np.outer(Aq, Aq) - (q @ Aq - 1.0) * A
    f = pin.focal_px
    r0, c0 = pin.principal_point_rc
    K = np.array([[f, 0.0, c0], [0.0, f, r0], [0.0, 0.0, 1.0]])
    Ki = np.linalg.inv(K)
    return Ki.T @ M @ Ki


def limb_truth(body: Body, pin: Pinhole) -> LimbTruth:
    """Body-centre image, limb ellipse, range and apparent radius of ``body`` (module docstring)."""
    C = limb_conic(body, pin)
    C2, lin = C[:2, :2], C[:2, 2]
    xc = np.linalg.solve(C2, -lin)  # (col, row)
    F = float(xc @ C2 @ xc + 2.0 * lin @ xc + C[2, 2])
    lam, V = np.linalg.eigh(C2 / -F)
    if not np.all(lam > 0):
        raise ValueError("the limb is not an ellipse in this view")
    axes = 1.0 / np.sqrt(lam)  # ascending eigenvalues: major first
    v = V[:, 0]  # (d col, d row) of the major axis
    ang = math.atan2(-v[1], v[0]) % math.pi
    bc = pin.project(body.center_cam)
    rng = body.range_km
    r_mean = float(np.cbrt(np.prod(body.radii)))
    app = pin.focal_px * math.tan(math.asin(r_mean / rng))
    return LimbTruth((float(bc[0]), float(bc[1])), (float(xc[1]), float(xc[0])), (float(axes[0]), float(axes[1])),
                     float(ang), rng, app)


def limb_distance_px(body: Body, pin: Pinhole, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Approximate signed distance (px) of image points from the limb, positive outside.

    ``(rho - 1)`` times the pixels per unit of ``rho`` (a ray moved by ``1/f`` rad moves its
    closest approach by ``range/f`` km, i.e. ``range / (f r_min)`` in the scaled frame with the
    smallest radius: the distance is not overestimated)."""
    rho = closest_approach(body, pin.directions(rows, cols).reshape(-1, 3))
    scale = body.range_km / (pin.focal_px * min(body.radii))
    return ((rho - 1.0) / scale).reshape(np.shape(rows))
