r"""The terminator of a triaxial ellipsoid lit by a distant Sun (Appendix II of Mortari et al. 2016).

Derivation
----------
A surface point :math:`x` (:math:`x^TJx = 1`, Eq. 1) has outward normal
:math:`n \propto Jx`.  For a distant Sun in the unit direction :math:`s`
(body frame, from the body toward the Sun) the point is lit when
:math:`(Jx)\cdot s > 0`, so the terminator is

.. math:: s^T J x = 0, \qquad x^T J x = 1   \qquad\text{(Eq. 21)}

-- the intersection of the ellipsoid with the plane through the centre whose
normal is :math:`n_t = Js` (the diametral plane *conjugate* to :math:`s`).  A
central plane section of an ellipsoid is an ellipse centred on the origin.
With :math:`y = J^{1/2}x` and :math:`w_s = J^{1/2}s` the conditions become
:math:`w_s^Ty = 0`, :math:`y^Ty = 1`: ``y`` runs over the great circle
orthogonal to :math:`w_s`.  Let :math:`P` (3x2) be an orthonormal basis of
:math:`w_s^\perp`; then :math:`x = J^{-1/2} P t` with :math:`|t| = 1`.  With the
SVD :math:`J^{-1/2}P = U\Sigma V^T`, the terminator is
:math:`x(\varphi) = \sigma_1 u_1\cos\varphi + \sigma_2 u_2\sin\varphi`: its
centre is the origin, its semi-axis vectors are :math:`\sigma_i u_i`
(orthogonal, both in the plane :math:`n_t^Tx = 0`).  (This is equivalent to the
paper's parametrisation Eq. (22), which fails when :math:`v_{s3} = 0`.)

Image.  With :math:`R` the body->camera rotation and :math:`q` the body centre
in the camera frame, a terminator point is
:math:`X = q + R(\sigma_1u_1\cos\varphi + \sigma_2u_2\sin\varphi) = H\,[\cos\varphi, \sin\varphi, 1]^T`,
:math:`H = [R\sigma_1u_1,\ R\sigma_2u_2,\ q]`, and its pixel is
:math:`h = [col, row, 1]^T \sim K H [\cos\varphi, \sin\varphi, 1]^T`.  The unit
circle is :math:`t^T Z t = 0`, :math:`Z = \mathrm{diag}(1, 1, -1)`; therefore the
terminator's image is the conic :math:`C_t = G^{-T} Z G^{-1}`, :math:`G = KH`
(negative inside the projected terminator ellipse).  :math:`G` is singular when
the camera lies in the terminator plane (:math:`q\cdot Rn_t = 0`, e.g. a
half-Moon): the terminator is then seen edge-on as a segment and no conic is
returned.  Only the arc with :math:`(Jx)\cdot(p - x) > 0`, i.e.
:math:`(Jx)\cdot p > 1` (:math:`p = -R^Tq`, the observer in the body frame),
faces the camera and is visible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import GeometryError, LimbInputError
from .camera import Camera
from .ellipsoid import check_radii, check_rotation, check_vec3

__all__ = ["TerminatorEllipse", "TerminatorImage", "terminator_ellipse", "terminator_image"]


def _unit(v: object, name: str) -> np.ndarray:
    x = check_vec3(v, name)
    n = float(np.linalg.norm(x))
    if not n > 0:
        raise LimbInputError(f"`{name}` must be a non-zero vector, got {x.tolist()}")
    return x / n


@dataclass(frozen=True, eq=False)
class TerminatorEllipse:
    """The terminator in the body frame: ``x(phi) = center + axes[0] cos(phi) + axes[1] sin(phi)``.

    Attributes
    ----------
    center
        Always the origin (km).
    axes
        ``(2, 3)``: the semi-major and semi-minor axis vectors (km, orthogonal).
    semi_axes
        Their lengths ``(major, minor)`` (km).
    normal
        Unit normal of the terminator plane, ``J s / |J s|`` (points to the lit side).
    sun_dir
        Unit Sun direction (body frame, body -> Sun).
    """

    center: np.ndarray
    axes: np.ndarray
    semi_axes: tuple[float, float]
    normal: np.ndarray
    sun_dir: np.ndarray

    def points(self, phi: np.ndarray) -> np.ndarray:
        """Body-frame points ``(n, 3)`` on the terminator at parameters ``phi`` (rad)."""
        phi = np.asarray(phi, dtype=float)
        return self.center + np.cos(phi)[..., None] * self.axes[0] + np.sin(phi)[..., None] * self.axes[1]


def terminator_ellipse(radii: object, sun_dir_body: object) -> TerminatorEllipse:
    """The terminator of the ellipsoid ``radii`` for a distant Sun along ``sun_dir_body`` (module docstring)."""
    r = check_radii(radii)
    s = _unit(sun_dir_body, "sun_dir_body")
    ws = s / r  # J^{1/2} s
    # orthonormal basis of ws-perp
    _, _, Vt = np.linalg.svd(ws[None, :])
    P = Vt[1:].T  # (3, 2)
    B = r[:, None] * P  # J^{-1/2} P
    U, sig, _ = np.linalg.svd(B, full_matrices=False)
    axes = (U * sig).T
    n = s / r**2
    return TerminatorEllipse(
        center=np.zeros(3),
        axes=axes,
        semi_axes=(float(sig[0]), float(sig[1])),
        normal=n / np.linalg.norm(n),
        sun_dir=s,
    )


@dataclass(frozen=True, eq=False)
class TerminatorImage:
    """The terminator seen by a camera.

    Attributes
    ----------
    ellipse
        The 3-D terminator (body frame).
    conic
        Pixel conic (order ``[col, row, 1]``, negative inside, unit norm) of the whole projected
        terminator ellipse (visible and hidden halves), or ``None`` when seen edge-on.
    R_body_to_camera, center_cam
        The pose used.
    camera
        The camera used.
    radii
        The ellipsoid semi-axes (km).
    """

    ellipse: TerminatorEllipse
    conic: np.ndarray | None
    R_body_to_camera: np.ndarray
    center_cam: np.ndarray
    camera: Camera
    radii: np.ndarray

    def points_cam(self, phi: np.ndarray) -> np.ndarray:
        """Camera-frame points (km) on the terminator."""
        return self.center_cam + self.ellipse.points(phi) @ self.R_body_to_camera.T

    def visible(self, phi: np.ndarray) -> np.ndarray:
        """Whether the terminator points at ``phi`` face the camera: ``(J x).p > 1``."""
        x = self.ellipse.points(phi)
        p = -self.R_body_to_camera.T @ self.center_cam
        return (x / self.radii**2) @ p > 1.0

    def visible_points_rc(self, n: int = 720) -> np.ndarray:
        """Image points ``(m, 2)`` ``(row, col)`` of the visible part of the terminator (``n`` samples)."""
        phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        X = self.points_cam(phi)
        vis = self.visible(phi) & (X[:, 2] > 0)
        return self.camera.project(X[vis])


def terminator_image(
    camera: Camera,
    radii: object,
    center_cam: object,
    R_body_to_camera: object,
    sun_dir_camera: object,
    edge_on_tol: float = 1e-9,
) -> TerminatorImage:
    """Terminator of the ellipsoid in the image (module docstring for the derivation).

    Parameters
    ----------
    camera, radii, center_cam, R_body_to_camera
        As in :func:`jaxlimb.geometry.ellipsoid.image_conic`.
    sun_dir_camera
        Unit vector from the body toward the Sun, camera frame.
    edge_on_tol
        ``|det H| / (|h1||h2||h3|)`` below which the terminator is treated as edge-on (``conic = None``).
    """
    r = check_radii(radii)
    q = check_vec3(center_cam, "center_cam")
    R = np.eye(3) if R_body_to_camera is None else check_rotation(R_body_to_camera)
    s_cam = _unit(sun_dir_camera, "sun_dir_camera")
    if not q[2] > 0:
        raise GeometryError(f"body centre must be in front of the camera (z > 0), got center_cam = {q.tolist()} km")
    term = terminator_ellipse(r, R.T @ s_cam)
    H = np.column_stack([R @ term.axes[0], R @ term.axes[1], q])
    nrm = np.prod(np.linalg.norm(H, axis=0))
    conic = None
    if abs(np.linalg.det(H)) > edge_on_tol * nrm:
        G = camera.K @ H
        Gi = np.linalg.inv(G)
        C = Gi.T @ np.diag([1.0, 1.0, -1.0]) @ Gi
        C = 0.5 * (C + C.T)
        conic = C / np.linalg.norm(C)
        # sign: negative inside.  Points of the plane inside the unit circle (t = 0 -> centre of
        # the ellipse, X = q) must give a negative value.
        hc = camera.K @ q
        if float(hc @ conic @ hc) > 0:
            conic = -conic
    return TerminatorImage(ellipse=term, conic=conic, R_body_to_camera=R, center_cam=q, camera=camera, radii=r)
