"""Pinhole camera model and the pixel / camera-frame conventions of docs/design.md.

Conventions (fixed):

* images are indexed ``[row, col]``; pixel ``(0, 0)`` is the *centre* of the
  top-left pixel; row grows downward, col to the right;
* camera frame: ``+z`` along the boresight, ``+x`` toward ``+col``, ``+y``
  toward ``+row``;
* pinhole projection ``col = cc + (f/pitch) x/z``, ``row = rc + (f/pitch) y/z``
  with principal point ``(rc, cc)``.

The default camera is the 1944x2592 imager of the illuminated-ellipsoid paper
(2.2 um pixels, 16 mm focal length).

Optional Brown--Conrady lens distortion
---------------------------------------
Five optional coefficients ``k1, k2, k3`` (radial) and ``p1, p2`` (tangential), all zero
by default (then every method is the plain pinhole model above, bit for bit).  They act
on the *normalised* image coordinates ``x = X/Z`` (toward +col), ``y = Y/Z`` (toward +row)
as in Brown (1966, "Decentering distortion of lenses", Photogramm. Eng. 32(3)) and the
OpenCV convention::

    r^2 = x^2 + y^2
    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y
    col = cc + f_px x_d,   row = rc + f_px y_d

The inverse (undistortion) has no closed form; :meth:`Camera.undistort_normalized`
solves it by Newton's method with the analytic 2x2 Jacobian, to 1e-15 in normalised
units (≈1e-11 px).  The camera file may carry the keys ``"k1", "k2", "k3", "p1", "p2"``
(optional; absent = 0).  A camera whose radial mapping is not monotonic inside the image
circle (the mapping folds over and cannot be inverted) is rejected with ``ConfigError``.

Range from apparent size
------------------------
For a sphere of radius ``R`` at range ``D`` the limb is a circular cone of half-angle
``alpha = asin(R/D)``.  On the boresight its image is a circle of radius
``r = f_px tan(alpha)`` (Eq. 36 of the Aerospace 2015 paper, ``r = (f/d) R/sqrt(D^2 - R^2)``),
so ``D = R / sin(atan(r / f_px))``.  Off-axis (centre direction at angle ``theta`` from the
boresight) the image is an ellipse elongated radially with (derivation in
:func:`sphere_image_ellipse`)::

    a = f sin(alpha) cos(alpha) / (cos^2 theta - sin^2 alpha)      (radial semi-axis)
    b = f sin(alpha) / sqrt(cos^2 theta - sin^2 alpha)              (tangential)

hence ``tan(alpha) = b^2 / (a f)`` **exactly, whatever theta** (:meth:`range_from_ellipse`),
while the on-axis formula applied to ``b`` gives ``sin(alpha)/cos(theta)``, i.e. a range short
by exactly the factor ``cos(theta)`` (2.4 % short at the corner of the default camera,
theta = 12.5 deg); applied to ``a`` it is shorter still.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from .._io import read_json_file
from .._schema import check_keys, explain
from .._validate import Range, number, vector
from ..errors import ConfigError, GeometryError

#: The Brown--Conrady coefficients, in the order of :attr:`Camera.distortion`.
_DISTORTION_KEYS = ("k1", "k2", "k3", "p1", "p2")
#: Largest image side accepted (px): beyond any detector, and a bound on every allocation sized by a camera.
_MAX_SIDE_PX = 100_000


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Parameters
    ----------
    focal_length_mm
        Focal length in mm (> 0).
    pixel_pitch_mm
        Pixel pitch in mm (> 0); square pixels.
    rows, cols
        Image size in pixels (>= 2 each).
    principal_point_rc
        Principal point ``(row, col)`` in pixels; ``None`` means the image centre
        ``((rows - 1) / 2, (cols - 1) / 2)``.
    k1, k2, k3, p1, p2
        Optional Brown--Conrady coefficients (module docstring), default 0 (pinhole).
    """

    focal_length_mm: float = 16.0
    pixel_pitch_mm: float = 2.2e-3
    rows: int = 1944
    cols: int = 2592
    principal_point_rc: tuple[float, float] | None = field(default=None)
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def __post_init__(self) -> None:
        s = object.__setattr__
        for name, rng in (("focal_length_mm", Range(0.0, 1e7, lo_open=True)), ("pixel_pitch_mm", Range(0.0, 1e3, lo_open=True))):
            s(self, name, number(getattr(self, name), f"camera `{name}`", rng))
        for name in ("rows", "cols"):
            s(self, name, number(getattr(self, name), f"camera `{name}`", Range(2, _MAX_SIDE_PX), integer=True))
        pp = self.principal_point_rc
        if pp is None:
            s(self, "principal_point_rc", ((self.rows - 1) / 2.0, (self.cols - 1) / 2.0))
        else:
            s(self, "principal_point_rc", vector(pp, "camera `principal_point_rc`", 2))
        for name in _DISTORTION_KEYS:
            s(self, name, number(getattr(self, name), f"camera distortion `{name}`"))
        if self.has_distortion:
            self._check_distortion_monotonic()

    # ------------------------------------------------------------------ constructors
    @classmethod
    def default(cls) -> Camera:
        """The paper's imager: 1944x2592, 2.2 um pixels, 16 mm focal length."""
        return cls()

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Camera:
        """Build from the camera-file dictionary (``jaxlimb/schemas/camera.schema.json``): an unknown key, a missing
        one, a wrong type or range is a :class:`~jaxlimb.errors.ConfigError` naming the key (an unknown key with
        the known key it most likely misspells)."""
        if not isinstance(d, dict):
            raise ConfigError(f"camera must be a JSON object, got {type(d).__name__}")
        check_keys(d, "camera", "camera")
        try:
            return cls(**d)
        except ConfigError as e:  # the schema's message, with the key path, when the file breaks the schema
            explain(d, "camera", "camera", e)

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> Camera:
        """Read a camera JSON file (``{"focal_length_mm", "pixel_pitch_mm", "rows", "cols", "principal_point_rc"}``)."""

        return cls.from_dict(read_json_file(path, "camera file"))

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["principal_point_rc"] = list(self.principal_point_rc)  # type: ignore[arg-type]
        for k in _DISTORTION_KEYS:  # optional keys: written only when non-zero
            if d[k] == 0.0:
                del d[k]
        return d

    # ------------------------------------------------------------------ properties
    @property
    def focal_px(self) -> float:
        """Focal length in pixels, ``f / pitch``."""
        return self.focal_length_mm / self.pixel_pitch_mm

    @property
    def shape(self) -> tuple[int, int]:
        return (self.rows, self.cols)

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix mapping camera ``[x, y, z]`` to homogeneous ``[col, row, 1]``."""
        f = self.focal_px
        rc, cc = self.principal_point_rc  # type: ignore[misc]
        return np.array([[f, 0.0, cc], [0.0, f, rc], [0.0, 0.0, 1.0]])

    # ------------------------------------------------------------------ distortion
    @property
    def has_distortion(self) -> bool:
        """True when any Brown--Conrady coefficient is non-zero."""
        return any(getattr(self, k) != 0.0 for k in _DISTORTION_KEYS)

    @property
    def distortion(self) -> tuple[float, float, float, float, float]:
        """``(k1, k2, k3, p1, p2)``."""
        return (self.k1, self.k2, self.k3, self.p1, self.p2)

    def _max_normalised_radius(self) -> float:
        r0, c0 = self.principal_point_rc  # type: ignore[misc]
        dr = max(r0, self.rows - 1 - r0) + 0.5
        dc = max(c0, self.cols - 1 - c0) + 0.5
        return math.hypot(dr, dc) / self.focal_px

    def _check_distortion_monotonic(self) -> None:
        # radial map r_d = r (1 + k1 r^2 + k2 r^4 + k3 r^6) must increase up to 1.25x the
        # image corner, else undistortion is ambiguous (the lens model folds over).
        rmax = 1.25 * self._max_normalised_radius()
        r = np.linspace(0.0, rmax, 2001)
        drd = 1 + 3 * self.k1 * r**2 + 5 * self.k2 * r**4 + 7 * self.k3 * r**6
        if np.any(drd <= 0.05):
            bad = float(r[np.argmax(drd <= 0.05)] * self.focal_px)
            raise ConfigError(
                f"camera distortion (k1, k2, k3) = {self.distortion[:3]} folds over at {bad:.1f} px "
                f"from the principal point (inside 1.25x the image corner, {rmax * self.focal_px:.1f} px); "
                "it cannot be inverted"
            )

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Brown--Conrady map of normalised coordinates ``(..., 2)`` as ``(x, y)`` (module docstring)."""
        xy = np.asarray(xy, dtype=float)
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        rad = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xd = x * rad + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
        yd = y * rad + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def distort_jacobian_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Jacobian ``d(x_d, y_d)/d(x, y)`` ``(..., 2, 2)`` of :meth:`distort_normalized`."""
        xy = np.asarray(xy, dtype=float)
        x, y = xy[..., 0], xy[..., 1]
        k1, k2, k3, p1, p2 = self.distortion
        r2 = x * x + y * y
        rad = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = k1 + 2 * k2 * r2 + 3 * k3 * r2 * r2  # d(rad)/d(r2)
        j = np.empty(xy.shape[:-1] + (2, 2))
        j[..., 0, 0] = rad + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x
        j[..., 0, 1] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
        j[..., 1, 0] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
        j[..., 1, 1] = rad + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x
        return j

    def undistort_normalized(self, xy_d: np.ndarray, tol: float = 1e-15, max_iter: int = 50) -> np.ndarray:
        """Inverse of :meth:`distort_normalized` by Newton's method.

        Starts from ``xy_d`` and iterates ``xy <- xy - J^-1 (distort(xy) - xy_d)``
        with the analytic Jacobian until the step is below ``tol`` (normalised units).

        Raises
        ------
        GeometryError
            No convergence within ``max_iter`` (a point far outside the calibrated field).
        """
        xy_d = np.asarray(xy_d, dtype=float)
        if not self.has_distortion:
            return xy_d.copy()
        xy = xy_d.copy()
        for _ in range(max_iter):
            res = self.distort_normalized(xy) - xy_d
            step = np.linalg.solve(self.distort_jacobian_normalized(xy), res[..., None])[..., 0]
            xy = xy - step
            if np.all(np.abs(step) <= tol * np.maximum(1.0, np.abs(xy))):
                return xy
        raise GeometryError(
            f"undistortion did not converge in {max_iter} Newton iterations "
            f"(max residual {float(np.max(np.abs(self.distort_normalized(xy) - xy_d))):.2e}); "
            "the point is outside the valid field of the distortion model"
        )

    def distort(self, rc: np.ndarray) -> np.ndarray:
        """Ideal (pinhole) pixel ``(..., 2)`` ``(row, col)`` -> distorted (observed) pixel."""
        rc_ = np.asarray(rc, dtype=float)
        r0, c0 = self.principal_point_rc  # type: ignore[misc]
        f = self.focal_px
        xy = np.stack([(rc_[..., 1] - c0) / f, (rc_[..., 0] - r0) / f], axis=-1)
        xyd = self.distort_normalized(xy)
        return np.stack([r0 + f * xyd[..., 1], c0 + f * xyd[..., 0]], axis=-1)

    def undistort(self, rc: np.ndarray) -> np.ndarray:
        """Distorted (observed) pixel ``(..., 2)`` ``(row, col)`` -> ideal (pinhole) pixel."""
        rc_ = np.asarray(rc, dtype=float)
        r0, c0 = self.principal_point_rc  # type: ignore[misc]
        f = self.focal_px
        xyd = np.stack([(rc_[..., 1] - c0) / f, (rc_[..., 0] - r0) / f], axis=-1)
        xy = self.undistort_normalized(xyd)
        return np.stack([r0 + f * xy[..., 1], c0 + f * xy[..., 0]], axis=-1)

    # ------------------------------------------------------------------ mapping
    def project(self, xyz: np.ndarray) -> np.ndarray:
        """Project camera-frame points ``(..., 3)`` to pixel ``(..., 2)`` as ``(row, col)``.

        Pinhole, followed by the Brown--Conrady distortion when the camera has one.
        """
        xyz = np.asarray(xyz, dtype=float)
        rc, cc = self.principal_point_rc  # type: ignore[misc]
        f = self.focal_px
        z = xyz[..., 2]
        if self.has_distortion:
            xyd = self.distort_normalized(np.stack([xyz[..., 0] / z, xyz[..., 1] / z], axis=-1))
            return np.stack([rc + f * xyd[..., 1], cc + f * xyd[..., 0]], axis=-1)
        return np.stack([rc + f * xyz[..., 1] / z, cc + f * xyz[..., 0] / z], axis=-1)

    def los(self, rc: np.ndarray) -> np.ndarray:
        """Unit line-of-sight vectors ``(..., 3)`` in the camera frame for pixels ``(..., 2)`` ``(row, col)``.

        Observed (distorted) pixels are undistorted first when the camera has distortion.
        """
        rc_ = np.asarray(rc, dtype=float)
        if self.has_distortion:
            rc_ = self.undistort(rc_)
        r0, c0 = self.principal_point_rc  # type: ignore[misc]
        f = self.focal_px
        v = np.stack([(rc_[..., 1] - c0) / f, (rc_[..., 0] - r0) / f, np.ones(rc_.shape[:-1])], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    pixel_to_los = los

    def los_to_pixel(self, los: np.ndarray) -> np.ndarray:
        """Pixel ``(row, col)`` of camera-frame directions ``(..., 3)`` (``z > 0`` required)."""
        los = np.asarray(los, dtype=float)
        if np.any(los[..., 2] <= 0):
            raise GeometryError("`los` must point in front of the camera (z > 0)")
        return self.project(los)

    def los_jacobian(self, rc: np.ndarray) -> np.ndarray:
        """Jacobian ``d(unit LOS)/d(row, col)`` ``(..., 3, 2)`` at observed pixels ``rc``.

        ``u = v/|v|`` with ``v = [x, y, 1]`` so ``du/dv = (I - u u^T)/|v|``; ``dv/d(col, row)``
        is ``I2/f_px`` through the inverse distortion Jacobian when there is distortion.
        Columns are ordered (row, col).
        """
        rc_ = np.asarray(rc, dtype=float)
        u = self.los(rc_)
        f = self.focal_px
        vnorm = 1.0 / u[..., 2]
        P = (np.eye(3) - u[..., :, None] * u[..., None, :]) / vnorm[..., None, None]
        # d(x, y)/d(col, row) of the normalised undistorted coordinates
        dxy = np.broadcast_to(np.eye(2) / f, rc_.shape[:-1] + (2, 2)).copy()
        if self.has_distortion:
            xy = u[..., :2] / u[..., 2:3]
            dxy = np.linalg.inv(self.distort_jacobian_normalized(xy)) / f
        dv = np.zeros(rc_.shape[:-1] + (3, 2))
        # columns: (row, col) -> swap the (col, row) order of dxy
        dv[..., :2, 0] = dxy[..., :, 1]
        dv[..., :2, 1] = dxy[..., :, 0]
        return P @ dv

    def radius_px(self, body_radius_km: float, range_km: float) -> float:
        """Apparent radius (px) of a sphere on the boresight: ``f_px * tan(asin(R / D))``."""
        if range_km <= body_radius_km:
            raise ConfigError(f"range_km must exceed body radius {body_radius_km}, got {range_km}")
        return self.focal_px * math.tan(math.asin(body_radius_km / range_km))

    def range_from_radius(self, radius_px: float, body_radius_km: float) -> float:
        """Range (km) of a sphere on the boresight from its apparent radius (Eq. 36 inverted).

        ``D = R / sin(atan(r_px / f_px))`` (``= R sqrt(1 + f_px^2 / r_px^2)``).  Exact on the
        boresight; off-axis use :meth:`range_from_ellipse`.
        """
        if not (math.isfinite(radius_px) and radius_px > 0):
            raise ConfigError(f"`radius_px` must be finite and > 0, got {radius_px!r}")
        if not (math.isfinite(body_radius_km) and body_radius_km > 0):
            raise ConfigError(f"`body_radius_km` must be finite and > 0, got {body_radius_km!r}")
        return body_radius_km / math.sin(math.atan(radius_px / self.focal_px))

    def range_from_ellipse(self, semi_major_px: float, semi_minor_px: float, body_radius_km: float) -> float:
        """Exact range (km) of a sphere anywhere in the (undistorted) field from its image ellipse.

        ``tan(alpha) = b^2 / (a f_px)`` (module docstring), ``D = R / sin(alpha)``.
        """
        a, b = float(semi_major_px), float(semi_minor_px)
        if not (math.isfinite(a) and math.isfinite(b) and a >= b * (1 - 1e-9) and b > 0):
            raise ConfigError(f"semi-axes must satisfy semi_major_px >= semi_minor_px > 0, got ({a!r}, {b!r})")
        if not (math.isfinite(body_radius_km) and body_radius_km > 0):
            raise ConfigError(f"`body_radius_km` must be finite and > 0, got {body_radius_km!r}")
        return body_radius_km / math.sin(math.atan(b * b / (a * self.focal_px)))


def sphere_image_ellipse(camera: Camera, center_cam: np.ndarray, body_radius_km: float) -> dict[str, Any]:
    """Exact pinhole image ellipse of a sphere (no distortion).

    Derivation.  Let the sphere centre be at angle ``theta`` from the boresight and
    ``alpha = asin(R/D)``.  The limb cone is symmetric about the plane (boresight, centre
    direction), so one ellipse axis is radial.  Its radial end points are the images of the
    limb rays at ``theta +- alpha``: ``rho = f tan(theta +- alpha)``, so the centre is at
    ``rho_0 = f [tan(theta+alpha) + tan(theta-alpha)]/2 = f sin(theta)cos(theta)/(cos^2 theta - sin^2 alpha)``
    and ``a = f [tan(theta+alpha) - tan(theta-alpha)]/2 = f sin(alpha)cos(alpha)/(cos^2 theta - sin^2 alpha)``.
    For the tangential semi-axis intersect the cone ``(u.w)^2 = cos^2(alpha) |w|^2`` with the
    image plane ``w = (rho, t, 1)`` (``rho`` radial, ``t`` tangential, unit focal length),
    ``u = (sin theta, 0, cos theta)``: ``(rho sin(theta) + cos(theta))^2 = cos^2(alpha)(rho^2 + t^2 + 1)``;
    at ``rho = rho_0`` the half-width is ``b = f sin(alpha) / sqrt(cos^2 theta - sin^2 alpha)``.
    So ``b^2/a = f tan(alpha)`` for every ``theta``.

    Returns
    -------
    dict
        ``center_rc`` (ellipse centre, not the image of the body centre), ``semi_axes_px``
        ``(a, b)`` with ``a`` radial (semi-major), ``angle_rad`` (direction of ``a`` in the
        convention of :mod:`jaxlimb.geometry.ellipsoid`: measured from ``+col`` toward ``-row``,
        i.e. ``a`` along ``(d_row, d_col) = (-sin angle, cos angle)``, reduced to ``[0, pi)``),
        ``body_center_rc`` (image of the centre), ``theta_rad``, ``alpha_rad``.
    """
    c = np.asarray(center_cam, dtype=float)
    D = float(np.linalg.norm(c))
    if not (body_radius_km > 0 and D > body_radius_km):
        raise GeometryError(f"observer must be outside the sphere: range {D} km, radius {body_radius_km} km")
    u = c / D
    th = math.acos(min(1.0, max(-1.0, u[2])))
    al = math.asin(body_radius_km / D)
    den = math.cos(th) ** 2 - math.sin(al) ** 2
    if den <= 0 or th + al >= math.pi / 2:
        raise GeometryError("the sphere's limb reaches the image plane at infinity (not an ellipse)")
    f = camera.focal_px
    rho0 = f * math.sin(th) * math.cos(th) / den
    a = f * math.sin(al) * math.cos(al) / den
    b = f * math.sin(al) / math.sqrt(den)
    phi = math.atan2(u[1], u[0]) if th > 0 else 0.0  # radial direction: (d_row, d_col) = (sin phi, cos phi)
    r0, c0 = camera.principal_point_rc  # type: ignore[misc]
    return {
        "center_rc": (r0 + rho0 * math.sin(phi), c0 + rho0 * math.cos(phi)),
        "semi_axes_px": (a, b),
        "angle_rad": (-phi) % math.pi,
        "body_center_rc": tuple(camera.project(u)),
        "theta_rad": th,
        "alpha_rad": al,
    }


__all__ = ["Camera", "sphere_image_ellipse"]
