r"""The limb cone of a triaxial ellipsoid and its image in a pinhole camera.

Implements Sec. III (Eq. 1-9) and the centre offset of Sec. IV of

    D. Mortari, C. N. D'Souza, R. Zanetti, "Image Processing of Illuminated
    Ellipsoid", J. Spacecraft and Rockets (2016)  -- "Mortari et al. 2016".

Conventions (docs/design.md): the body-fixed frame is centred on the ellipsoid with
its axes along the semi-axes ``radii = (a, b, c)`` so that the surface is
:math:`x^T J x = 1`, :math:`J = \mathrm{diag}(a^{-2}, b^{-2}, c^{-2})` (Eq. 1).
Positions are in km.  Images are ``[row, col]``; pixel ``(0, 0)`` is the centre
of the top-left pixel.

Conics and the ellipse angle convention: :mod:`jaxlimb.geometry.conic`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import AttitudeError, GeometryError, LimbInputError
from .camera import Camera
from .conic import conic_eval, conic_to_ellipse, ellipse_points, normalise_conic

__all__ = [
    "ImageConic",
    "LimbCone",
    "check_radii",
    "check_vec3",
    "check_rotation",
    "gamma_off",
    "image_conic",
    "limb_cone",
    "limb_cone_matrix",
    "limb_cone_matrix_camera",
    "projected_center",
]


# =============================================================================== validation
def check_radii(radii: object, name: str = "radii") -> np.ndarray:
    """Validate ellipsoid semi-axes ``(a, b, c)`` (km): three finite numbers > 0.

    A single number is accepted as a sphere.  Raises :class:`GeometryError`.
    """
    try:
        r = np.asarray(radii, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError(f"`{name}` must be three numbers (a, b, c) in km, got {radii!r}") from None
    if r.ndim == 0:
        r = np.full(3, float(r))
    if r.shape != (3,):
        raise GeometryError(f"`{name}` must have shape (3,), got shape {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise GeometryError(f"`{name}` must be finite and > 0 (degenerate ellipsoid), got {r.tolist()}")
    return r


def check_vec3(v: object, name: str) -> np.ndarray:
    try:
        x = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise LimbInputError(f"`{name}` must be a 3-vector, got {v!r}") from None
    if x.shape != (3,):
        raise LimbInputError(f"`{name}` must have shape (3,), got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise LimbInputError(f"`{name}` must be finite, got {x.tolist()}")
    return x


def check_rotation(R: object, name: str = "R_body_to_camera", tol: float = 1e-8) -> np.ndarray:
    """Validate a proper rotation matrix (orthonormal to ``tol``, det = +1); raises :class:`AttitudeError`."""
    try:
        M = np.asarray(R, dtype=float)
    except (TypeError, ValueError):
        raise AttitudeError(f"`{name}` must be a 3x3 rotation matrix, got {R!r}") from None
    if M.shape != (3, 3) or not np.all(np.isfinite(M)):
        raise AttitudeError(f"`{name}` must be a finite 3x3 matrix, got shape {M.shape}")
    err = float(np.max(np.abs(M @ M.T - np.eye(3))))
    det = float(np.linalg.det(M))
    if err > tol or det < 0:
        raise AttitudeError(
            f"`{name}` must be a proper rotation (|R R^T - I| <= {tol:g}, det = +1), "
            f"got |R R^T - I| = {err:.3g}, det = {det:.6g}"
        )
    return M


def _gamma(radii: np.ndarray, p: np.ndarray) -> float:
    return float(np.sum((p / radii) ** 2))


# =============================================================================== limb cone
def limb_cone_matrix(radii: object, p: object) -> np.ndarray:
    r"""Limb-cone matrix :math:`M = J p p^T J - (p^T J p - 1) J` (Eq. 2 of Mortari et al. 2016).

    A direction :math:`v` from the observer is tangent to the ellipsoid iff
    :math:`v^T M v = 0`; it hits the body iff :math:`v^T M v > 0` (and points
    toward it).  Derivation: the ray :math:`x = p + t v` meets
    :math:`x^T J x = 1` where
    :math:`t^2 v^TJv + 2t\,v^TJp + p^TJp - 1 = 0`, whose discriminant/4 is
    :math:`(v^TJp)^2 - (p^TJp-1)\,v^TJv = v^T M v`.

    Parameters
    ----------
    radii
        Semi-axes ``(a, b, c)`` in km (finite, > 0).
    p
        Observer position in the body frame (km); must be outside the ellipsoid.

    Raises
    ------
    GeometryError
        Degenerate radii, or the observer inside / on the ellipsoid (:math:`p^TJp \le 1`).
    """
    r = check_radii(radii)
    pv = check_vec3(p, "p")
    g = _gamma(r, pv)
    if not g > 1.0:
        raise GeometryError(
            f"observer `p` must be outside the ellipsoid (p^T J p > 1), got p^T J p = {g:.6g} for p = {pv.tolist()} km"
        )
    J = np.diag(r**-2.0)
    Jp = J @ pv
    return np.outer(Jp, Jp) - (g - 1.0) * J


def limb_cone_matrix_camera(radii: object, center_cam: object, R_body_to_camera: object) -> np.ndarray:
    r"""The limb-cone matrix in the camera frame, with the observer at the origin.

    With :math:`q` the body centre in the camera frame and
    :math:`A = R J R^T` (:math:`R` = body->camera), the observer sits at
    :math:`p = -R^T q` in the body frame and :math:`R M R^T =
    (A q)(A q)^T - (q^T A q - 1) A`; a camera ray :math:`d` is tangent iff
    :math:`d^T M_{cam} d = 0`.
    """
    q = check_vec3(center_cam, "center_cam")
    R = check_rotation(R_body_to_camera)
    M = limb_cone_matrix(radii, -R.T @ q)
    Mc = R @ M @ R.T
    return 0.5 * (Mc + Mc.T)


@dataclass(frozen=True, eq=False)
class LimbCone:
    r"""Eigen-analysis of the limb cone (Sec. III of Mortari et al. 2016), body frame.

    Attributes
    ----------
    M
        The cone matrix of Eq. (2).
    eigenvalues
        :math:`(\lambda_1, \lambda_2, \lambda_3)` with :math:`\lambda_1, \lambda_2 < 0 < \lambda_3`
        and :math:`|\lambda_1| \le |\lambda_2|` (so :math:`\xi_1 \ge \xi_2`, :math:`a' \ge b'`).
    C_ie
        Orthogonal matrix (det +1) whose columns are the eigenvectors
        :math:`\hat w_1, \hat w_2, \hat w_3` in the body frame: ``v = C_ie @ w`` (Eq. 3).
        The third column is the cone axis.
    xi
        :math:`\xi_i = |\lambda_i|^{-1/2}` (Eq. 7).
    semi_axes
        :math:`(a', b')` of Eq. (8): the sines of the cone's two half-angles (a' >= b').
    rho
        :math:`\rho = b'/a'` (Eq. 9).
    axis
        Unit cone axis (= ``C_ie[:, 2]``), pointing from the observer toward the body.
    gamma
        :math:`\gamma = p^T J p > 1`.
    gamma_off
        Angle (rad) between the cone axis and the direction to the body centre (Sec. IV).
    p
        Observer position (body frame, km).
    """

    M: np.ndarray
    eigenvalues: np.ndarray
    C_ie: np.ndarray
    xi: np.ndarray
    semi_axes: tuple[float, float]
    rho: float
    axis: np.ndarray
    gamma: float
    gamma_off: float
    p: np.ndarray

    @property
    def half_angles(self) -> tuple[float, float]:
        """The cone half-angles (rad) along ``w_1`` and ``w_2``: ``asin(a'), asin(b')``."""
        return (math.asin(self.semi_axes[0]), math.asin(self.semi_axes[1]))

    def directions(self, phi: np.ndarray) -> np.ndarray:
        """Unit tangent directions on the cone (body frame), ``(n, 3)``, parametrised by ``phi`` (rad).

        ``w = (a' cos phi, b' sin phi, sqrt(1 - a'^2 cos^2 phi - b'^2 sin^2 phi))`` satisfies
        Eq. (7) on the unit sphere; ``v = C_ie w``.
        """
        phi = np.asarray(phi, dtype=float)
        a, b = self.semi_axes
        w1, w2 = a * np.cos(phi), b * np.sin(phi)
        w3 = np.sqrt(np.clip(1.0 - w1**2 - w2**2, 0.0, None))
        return np.stack([w1, w2, w3], axis=-1) @ self.C_ie.T


def _angle_between(u: np.ndarray, v: np.ndarray) -> float:
    return float(math.atan2(np.linalg.norm(np.cross(u, v)), float(np.dot(u, v))))


def limb_cone(radii: object, p: object) -> LimbCone:
    r"""Eigen-decomposition of the limb cone, Eq. (2)-(9) of Mortari et al. 2016.

    :math:`M = C_{ie}\Lambda C_{ie}^T`; by Sec. III-A, :math:`\det M = (1-\gamma)^2\det J > 0`
    (Eq. 6), so one eigenvalue is positive (the cone axis) and two are negative.
    With :math:`|\lambda_i| = \xi_i^{-2}` the cone is
    :math:`w_1^2/\xi_1^2 + w_2^2/\xi_2^2 = w_3^2/\xi_3^2` (Eq. 7) and its trace on the
    unit sphere has semi-axes :math:`a' = \xi_1/\sqrt{\xi_1^2+\xi_3^2}`,
    :math:`b' = \xi_2/\sqrt{\xi_2^2+\xi_3^2}` (Eq. 8), ratio :math:`\rho=b'/a'` (Eq. 9).

    Raises
    ------
    GeometryError
        Degenerate radii, observer inside/on the ellipsoid, or a numerically
        degenerate eigen-structure (should not happen for valid inputs).
    """
    r = check_radii(radii)
    pv = check_vec3(p, "p")
    M = limb_cone_matrix(r, pv)
    M = 0.5 * (M + M.T)
    lam, V = np.linalg.eigh(M)  # ascending
    if not (lam[0] < 0 and lam[1] < 0 and lam[2] > 0):
        raise GeometryError(
            f"limb cone eigenvalues must have signs (-, -, +), got {lam.tolist()} (p = {pv.tolist()})"
        )
    # order: lambda_1 = the negative one closest to zero (xi_1 >= xi_2), lambda_2, lambda_3 > 0
    order = [1, 0, 2]
    lam = lam[order]
    V = V[:, order]
    axis = V[:, 2]
    if float(np.dot(axis, -pv)) < 0:
        V[:, 2] = -axis
    if np.linalg.det(V) < 0:
        V[:, 1] = -V[:, 1]
    xi = np.abs(lam) ** -0.5
    a_ = float(xi[0] / math.hypot(xi[0], xi[2]))
    b_ = float(xi[1] / math.hypot(xi[1], xi[2]))
    axis = V[:, 2].copy()
    return LimbCone(
        M=M,
        eigenvalues=lam,
        C_ie=V,
        xi=xi,
        semi_axes=(a_, b_),
        rho=b_ / a_,
        axis=axis,
        gamma=_gamma(r, pv),
        gamma_off=_angle_between(axis, -pv),
        p=pv,
    )


def gamma_off(radii: object, p: object) -> float:
    r"""Centre-offset angle :math:`\gamma_{off}` (rad), Sec. IV of Mortari et al. 2016.

    The angle between the limb-cone axis :math:`\hat v_c = C_{ie}\{0,0,1\}^T`
    (the centre of the observed ellipse on the unit sphere, Eq. 7-8) and the direction
    from the observer to the body centre, :math:`-\hat p`.  (On a pinhole image the
    centre of the limb ellipse lies along :math:`\hat v_c` only when the boresight is
    along it; elsewhere perspective moves it further -- see :class:`ImageConic`, which
    reports both the ellipse centre and the projected body centre.)  Zero for a sphere; for the Earth
    it depends on distance and latitude only (the paper's Fig. 3).  Always >= 0; the
    sign convention of Fig. 3 (negative south of the equator) is given by
    :func:`gamma_off_signed`.
    """
    return limb_cone(radii, p).gamma_off


def gamma_off_signed(radii: object, p: object, pole: object = (0.0, 0.0, 1.0)) -> float:
    r""":math:`\gamma_{off}` (rad) with the sign convention of Fig. 3 of Mortari et al. 2016.

    The magnitude is :func:`gamma_off`; the sign is that of the observer's latitude
    (:math:`\mathrm{sign}(p\cdot\text{pole})`): positive for northern, negative for southern
    observers, zero in the equatorial plane.  For an oblate body the cone axis is turned
    from :math:`-\hat p` toward the equator (toward ``-pole`` for a northern observer);
    :func:`gamma_off_direction` gives the full deviation vector.
    """
    cone = limb_cone(radii, p)
    pole_v = check_vec3(pole, "pole")
    s = float(np.dot(cone.p, pole_v))
    return 0.0 if s == 0 else math.copysign(cone.gamma_off, s)


def gamma_off_direction(radii: object, p: object) -> np.ndarray:
    r"""Unit vector (body frame) of the cone axis' deviation from :math:`-\hat p`.

    The component of :math:`\hat v_c` orthogonal to :math:`\hat p`, normalised; the
    Earth-offset correction of Sec. IV rotates :math:`\hat v_c` by :math:`\gamma_{off}`
    against this direction to get the body-centre direction.  Zero vector for a sphere.
    """
    cone = limb_cone(radii, p)
    ph = cone.p / np.linalg.norm(cone.p)
    d = cone.axis - np.dot(cone.axis, -ph) * (-ph)
    n = float(np.linalg.norm(d))
    return d / n if n > 1e-15 else np.zeros(3)


__all__ += ["gamma_off_signed", "gamma_off_direction"]


# =============================================================================== image
def projected_center(camera: Camera, center_cam: object) -> tuple[float, float]:
    """Pinhole projection ``(row, col)`` of the body centre (not the limb-ellipse centre)."""
    q = check_vec3(center_cam, "center_cam")
    if not q[2] > 0:
        raise GeometryError(f"body centre must be in front of the camera (z > 0), got center_cam = {q.tolist()} km")
    rc = camera.project(q)
    return float(rc[0]), float(rc[1])


@dataclass(frozen=True, eq=False)
class ImageConic:
    """The limb of an ellipsoid in the image, as a conic and as an ellipse.

    Attributes
    ----------
    conic
        3x3 symmetric matrix on ``[col, row, 1]``; negative inside, unit Frobenius norm.
    center_rc
        Centre ``(row, col)`` of the limb ellipse (NOT the image of the body centre).
    semi_axes_px
        ``(a, b)``, ``a >= b``.
    angle_rad
        Direction of the semi-major axis, ``[0, pi)``, counter-clockwise from ``+col`` as
        displayed: the axis is along ``(d_row, d_col) = (-sin, cos)`` (module docstring).
    body_center_rc
        Pinhole projection ``(row, col)`` of the body centre.
    cone_camera
        The limb-cone matrix in the camera frame (observer at the origin).
    """

    conic: np.ndarray
    center_rc: tuple[float, float]
    semi_axes_px: tuple[float, float]
    angle_rad: float
    body_center_rc: tuple[float, float]
    cone_camera: np.ndarray

    @property
    def rho(self) -> float:
        """Axis ratio ``b/a`` of the image ellipse."""
        return self.semi_axes_px[1] / self.semi_axes_px[0]

    @property
    def center_offset_px(self) -> float:
        """Distance (px) between the limb-ellipse centre and the projected body centre."""
        return float(math.hypot(self.center_rc[0] - self.body_center_rc[0], self.center_rc[1] - self.body_center_rc[1]))

    def evaluate(self, rc: np.ndarray) -> np.ndarray:
        """Conic value at ``(row, col)`` points (negative inside)."""
        return conic_eval(self.conic, rc)

    def points(self, n: int = 360) -> np.ndarray:
        """``n`` points ``(row, col)`` on the limb ellipse."""
        phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        return ellipse_points(self.center_rc, self.semi_axes_px, self.angle_rad, phi)

    def bbox_rc(self) -> tuple[float, float, float, float]:
        """Axis-aligned bounding box ``(row_min, row_max, col_min, col_max)`` of the ellipse."""
        a, b = self.semi_axes_px
        ct, st = math.cos(self.angle_rad), math.sin(self.angle_rad)
        hc = math.sqrt((a * ct) ** 2 + (b * st) ** 2)
        hr = math.sqrt((a * st) ** 2 + (b * ct) ** 2)
        r0, c0 = self.center_rc
        return (r0 - hr, r0 + hr, c0 - hc, c0 + hc)

    def as_dict(self) -> dict[str, object]:
        """The docs/design.md ``ellipse`` JSON object (plus the projected body centre)."""
        return {
            "center_rc": list(self.center_rc),
            "semi_axes_px": list(self.semi_axes_px),
            "angle_rad": self.angle_rad,
            "body_center_rc": list(self.body_center_rc),
        }


def _checked_pose(radii: object, center_cam: object, R_body_to_camera: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`image_conic`'s radii, body centre (in front of the camera) and rotation, checked."""
    r = check_radii(radii)
    q = check_vec3(center_cam, "center_cam")
    R = np.eye(3) if R_body_to_camera is None else check_rotation(R_body_to_camera)
    if not q[2] > 0:
        raise GeometryError(f"body centre must be in front of the camera (z > 0), got center_cam = {q.tolist()} km")
    return r, q, R


def image_conic(
    camera: Camera, radii: object, center_cam: object, R_body_to_camera: object = None
) -> ImageConic:
    r"""The limb of an ellipsoid as a conic in pixel coordinates.

    Derivation.  In the camera frame (observer at the origin) let :math:`q` be
    the body centre and :math:`A = R J R^T`.  A ray :math:`X = t d` meets
    :math:`(X-q)^T A (X-q) = 1` where
    :math:`t^2 d^TAd - 2t\,d^TAq + q^TAq - 1 = 0`; it is tangent when the
    discriminant vanishes:

    .. math:: d^T\left[(Aq)(Aq)^T - (q^TAq - 1)A\right] d = d^T M_c d = 0,

    which is Eq. (2) of Mortari et al. 2016 rotated to the camera frame
    (:math:`M_c = R M R^T` with :math:`p = -R^T q`).  A pixel ``(row, col)`` has
    the ray :math:`d = K^{-1} h`, :math:`h = [col, row, 1]^T`, hence the pixel conic

    .. math:: C \propto -K^{-T} M_c K^{-1}, \qquad h^T C h = 0,

    with the sign flipped so that pixels on the disk (:math:`d^TM_cd > 0`, the ray
    hits) give :math:`h^TCh < 0`.  The ellipse parameters follow from
    :func:`conic_to_ellipse`.

    Parameters
    ----------
    camera
        The pinhole :class:`~jaxlimb.geometry.camera.Camera`.
    radii
        Semi-axes ``(a, b, c)`` km.
    center_cam
        Body centre in the camera frame (km); must have ``z > 0``.
    R_body_to_camera
        Rotation taking body-fixed vectors to the camera frame (identity if ``None``).

    Raises
    ------
    GeometryError
        Camera inside the body, body centre behind the camera, or the limb cone
        not entirely in front of the camera (the image of the limb is then not an ellipse).
    """
    r, q, R = _checked_pose(radii, center_cam, R_body_to_camera)
    Mc = limb_cone_matrix_camera(r, q, R)
    Kinv = np.linalg.inv(camera.K)
    C = -(Kinv.T @ Mc @ Kinv)
    body_rc = projected_center(camera, q)
    C = normalise_conic(C, inside_rc=body_rc)
    try:
        center_rc, axes, theta = conic_to_ellipse(C)
    except GeometryError as e:
        raise GeometryError(
            f"the limb of the body is not an ellipse in the image (body too close / too far off-axis): {e}"
        ) from None
    return ImageConic(
        conic=C,
        center_rc=center_rc,
        semi_axes_px=axes,
        angle_rad=theta,
        body_center_rc=body_rc,
        cone_camera=Mc,
    )
