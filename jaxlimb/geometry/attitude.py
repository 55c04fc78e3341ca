"""Attitude representations, validation, and attitude from an observed body.

Conventions
-----------
* ``C_ci`` (docs/design.md) is the direction-cosine matrix that moves vectors from the
  inertial frame (ICRF/J2000) to the camera frame: ``v_c = C_ci @ v_i``.
* Quaternions are **scalar-last** by default, ``q = [q1, q2, q3, q4] = [e sin(phi/2),
  cos(phi/2)]`` (Shuster / JPL convention, the one of Mortari's refs [16, 17]). Every
  function that takes or returns a quaternion has an explicit ``order`` argument:
  ``"xyzw"`` (scalar-last, default) or ``"wxyz"`` (scalar-first).
* The quaternion -> DCM map is Shuster's attitude matrix (Shuster 1993, "A survey of
  attitude representations", J. Astronaut. Sci. 41(4))::

      A(q) = (q4^2 - |q_v|^2) I + 2 q_v q_v^T - 2 q4 [q_v x]

  For ``q = [e sin(phi/2), cos(phi/2)]`` this is ``cos(phi) I + (1 - cos(phi)) e e^T
  - sin(phi) [e x]``: the *frame* rotation by ``+phi`` about ``e`` (a passive rotation).
  ``A(q)`` is used as ``C_ci`` (inertial -> camera).  ``q`` and ``-q`` give the same
  matrix; :func:`dcm_to_quat` returns the representative with ``q4 >= 0``.
* Small attitude errors are rotation vectors ``dphi`` (rad) in the **camera frame**,
  ``C_est = (I - [dphi x]) C_true`` to first order (the multiplicative error of
  Markley & Crassidis 2014, *Fundamentals of Spacecraft Attitude Determination and Control*).

Attitude from the body (Mortari, D'Souza & Zanetti, closing side note of §VI)
---------------------------------------------------------------------------
The body-centre direction and the symmetry axis of the illuminated area are two
directions known in both frames.  With the camera frame vectors

* ``b1 = u_c`` (unit LOS to the body centre) and
* ``b2`` = unit vector perpendicular to ``u_c`` in the observer-body-Sun plane,
  pointing to the lit side (the symmetry axis of the illuminated area, lifted from the
  image onto the sphere of directions at the body centre),

and the inertial vectors ``r1 = unit(r_body - r_obs)`` and ``r2 = unit(s - (s.r1) r1)``
with ``s = unit(r_sun - r_body)``, the camera attitude follows from a weighted
single-point method.  We use Davenport's q-method (optimal for Wahba's problem) with
weights ``1/sigma_i^2`` and Shuster's QUEST covariance
``P = (sum_i w_i (I - b_i b_i^T))^-1`` (Shuster & Oh 1981, doi:10.2514/3.19717).
Because ``b2`` is perpendicular to ``b1`` the covariance is diagonal in the basis
``(u_c, e2, e3)``: the two rotations that move the body direction are known to
``sigma_center`` (about the same as the LOS), the **rotation about the body direction is
known only to ``sigma_axis``**, the (much larger) error of the symmetry-axis angle in the
image.  It becomes unobservable at zero or 180 deg phase (full/new body: no axis).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import AttitudeError, GeometryError

QuatOrder = Literal["xyzw", "wxyz"]

ARCSEC_PER_RAD = 180.0 / np.pi * 3600.0


# ----------------------------------------------------------------------------- helpers
def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v x]`` so that ``skew(v) @ w == np.cross(v, w)``."""
    v = np.asarray(v, dtype=float)
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _check_order(order: str) -> None:
    if order not in ("xyzw", "wxyz"):
        raise AttitudeError(f"quaternion `order` must be 'xyzw' (scalar-last) or 'wxyz' (scalar-first), got {order!r}")


def _as_xyzw(q: np.ndarray, order: str) -> np.ndarray:
    _check_order(order)
    q = np.asarray(q, dtype=float)
    if q.shape != (4,):
        raise AttitudeError(f"quaternion `q` must have shape (4,), got {q.shape}")
    return q if order == "xyzw" else np.array([q[1], q[2], q[3], q[0]])


def _from_xyzw(q: np.ndarray, order: str) -> np.ndarray:
    return q if order == "xyzw" else np.array([q[3], q[0], q[1], q[2]])


# ----------------------------------------------------------------------------- validation
def validate_dcm(C: np.ndarray, tol: float = 1e-6, name: str = "C_ci") -> np.ndarray:
    """Return ``C`` as a float (3, 3) array after checking it is a proper rotation.

    Raises
    ------
    AttitudeError
        If ``C`` is not 3x3 and finite, if ``max|C^T C - I| > tol`` (not orthonormal) or
        if ``|det C - 1| > tol`` (a reflection has ``det = -1``).
    """
    C = np.asarray(C, dtype=float)
    if C.shape != (3, 3):
        raise AttitudeError(f"`{name}` must be a 3x3 matrix, got shape {C.shape}")
    if not np.all(np.isfinite(C)):
        raise AttitudeError(f"`{name}` must be finite, got {C.tolist()}")
    ortho = float(np.max(np.abs(C.T @ C - np.eye(3))))
    if ortho > tol:
        raise AttitudeError(
            f"`{name}` is not orthonormal: max|C^T C - I| = {ortho:.3e} exceeds the tolerance {tol:.1e}"
        )
    det = float(np.linalg.det(C))
    if abs(det - 1.0) > tol:
        raise AttitudeError(f"`{name}` is not a proper rotation: det = {det:.6f}, expected +1 within {tol:.1e}")
    return C


def validate_quaternion(q: np.ndarray, order: QuatOrder = "xyzw", tol: float = 1e-6) -> np.ndarray:
    """Check ``| |q| - 1 | <= tol`` and return the normalised quaternion (same ``order``)."""
    qx = _as_xyzw(q, order)
    if not np.all(np.isfinite(qx)):
        raise AttitudeError(f"quaternion `q` must be finite, got {np.asarray(q).tolist()}")
    nrm = float(np.linalg.norm(qx))
    if abs(nrm - 1.0) > tol:
        raise AttitudeError(f"quaternion `q` must have unit norm within {tol:.1e}, got |q| = {nrm:.9f}")
    return _from_xyzw(qx / nrm, order)


# ----------------------------------------------------------------------------- conversions
def quat_to_dcm(q: np.ndarray, order: QuatOrder = "xyzw", tol: float = 1e-6) -> np.ndarray:
    """Shuster attitude matrix ``A(q)`` (module docstring), used as ``C_ci``."""
    qx = _as_xyzw(validate_quaternion(q, order, tol), order)
    v, w = qx[:3], qx[3]
    return (w * w - v @ v) * np.eye(3) + 2.0 * np.outer(v, v) - 2.0 * w * skew(v)


def dcm_to_quat(C: np.ndarray, order: QuatOrder = "xyzw", tol: float = 1e-6) -> np.ndarray:
    """Inverse of :func:`quat_to_dcm` (Shepperd's method, scalar part >= 0)."""
    _check_order(order)
    A = validate_dcm(C, tol)
    tr = np.trace(A)
    # Shepperd (1978): pick the largest of 4 q4^2, 4 q1^2, ... for stability.
    cand = np.array([A[0, 0], A[1, 1], A[2, 2], tr])
    i = int(np.argmax(cand))
    if i == 3:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = np.array([(A[1, 2] - A[2, 1]) / (4 * w), (A[2, 0] - A[0, 2]) / (4 * w), (A[0, 1] - A[1, 0]) / (4 * w), w])
    else:
        j, k = (i + 1) % 3, (i + 2) % 3
        qi = 0.5 * np.sqrt(1.0 + 2 * A[i, i] - tr)
        q = np.empty(4)
        q[i] = qi
        q[j] = (A[i, j] + A[j, i]) / (4 * qi)
        q[k] = (A[i, k] + A[k, i]) / (4 * qi)
        q[3] = (A[j, k] - A[k, j]) / (4 * qi)
    if q[3] < 0:
        q = -q
    q /= np.linalg.norm(q)
    return _from_xyzw(q, order)


def rotation_vector_to_dcm(phi: np.ndarray) -> np.ndarray:
    """Exact DCM of the frame rotation by ``|phi|`` about ``phi/|phi|`` (Rodrigues).

    ``C = cos(a) I + (1 - cos a) e e^T - sin(a) [e x]``, ``≈ I - [phi x]`` for small ``phi``.
    """
    phi = np.asarray(phi, dtype=float)
    a = float(np.linalg.norm(phi))
    if a < 1e-12:
        return np.eye(3) - skew(phi)
    e = phi / a
    return np.cos(a) * np.eye(3) + (1 - np.cos(a)) * np.outer(e, e) - np.sin(a) * skew(e)


def attitude_error_vector(C_est: np.ndarray, C_true: np.ndarray) -> np.ndarray:
    """Rotation vector ``dphi`` (rad, camera frame) with ``C_est = A(dphi) C_true``."""
    dC = validate_dcm(C_est, name="C_est") @ validate_dcm(C_true, name="C_true").T
    q = dcm_to_quat(dC)
    s = float(np.linalg.norm(q[:3]))
    if s < 1e-15:
        return np.zeros(3)
    ang = 2.0 * np.arctan2(s, q[3])
    return q[:3] / s * ang


def attitude_error_angle(C_est: np.ndarray, C_true: np.ndarray) -> float:
    """Total rotation angle (rad) between two attitudes."""
    return float(np.linalg.norm(attitude_error_vector(C_est, C_true)))


# ----------------------------------------------------------------------------- Wahba
def _unit_rows(v: np.ndarray, name: str) -> np.ndarray:
    v = np.atleast_2d(np.asarray(v, dtype=float))
    if v.ndim != 2 or v.shape[1] != 3:
        raise GeometryError(f"`{name}` must have shape (n, 3), got {v.shape}")
    n = np.linalg.norm(v, axis=1)
    if not np.all(np.isfinite(v)) or np.any(n < 1e-12):
        raise GeometryError(f"`{name}` must be finite, non-zero vectors")
    return v / n[:, None]


def davenport_q_method(b: np.ndarray, r: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Optimal ``C`` (reference -> body) minimising Wahba's loss ``sum w |b_i - C r_i|^2``.

    Davenport's q-method: with ``B = sum w_i b_i r_i^T``, ``S = B + B^T``,
    ``sigma = tr B``, ``z = sum w_i b_i x r_i``, the optimal scalar-last quaternion is the
    eigenvector of ``K = [[S - sigma I, z], [z^T, sigma]]`` with the largest eigenvalue
    (Markley & Crassidis 2014, ch. 5); ``C = A(q)``.

    Raises
    ------
    GeometryError
        Fewer than two non-parallel vector pairs (the solution is not unique).
    """
    b = _unit_rows(b, "b")
    r = _unit_rows(r, "r")
    w = np.asarray(weights, dtype=float).ravel()
    if b.shape != r.shape or w.shape != (b.shape[0],):
        raise GeometryError(f"`b`, `r`, `weights` must have n rows, got {b.shape}, {r.shape}, {w.shape}")
    if np.any(~np.isfinite(w)) or np.any(w <= 0):
        raise GeometryError(f"`weights` must be finite and > 0, got {w.tolist()}")
    cross_b = np.linalg.norm(np.cross(b[:, None, :], b[None, :, :]), axis=-1)
    if cross_b.max() < 1e-10:
        raise GeometryError("attitude needs at least two non-parallel directions; all `b` are parallel")
    B = np.einsum("i,ij,ik->jk", w, b, r)
    S = B + B.T
    sig = np.trace(B)
    z = np.einsum("i,ij->j", w, np.cross(b, r))
    K = np.zeros((4, 4))
    K[:3, :3] = S - sig * np.eye(3)
    K[:3, 3] = z
    K[3, :3] = z
    K[3, 3] = sig
    vals, vecs = np.linalg.eigh(K)
    q = vecs[:, -1]
    if q[3] < 0:
        q = -q
    return quat_to_dcm(q / np.linalg.norm(q))


def quest_covariance(b: np.ndarray, sigmas: np.ndarray) -> np.ndarray:
    """QUEST attitude-error covariance ``P = (sum_i sigma_i^-2 (I - b_i b_i^T))^-1`` (rad^2, body frame).

    Shuster's QUEST measurement model: each unit vector is perturbed isotropically
    perpendicular to itself with per-axis standard deviation ``sigma_i`` (rad).
    """
    b = _unit_rows(b, "b")
    s = np.asarray(sigmas, dtype=float).ravel()
    F = sum((1.0 / si**2) * (np.eye(3) - np.outer(bi, bi)) for bi, si in zip(b, s))
    if np.linalg.cond(F) > 1e14:
        raise GeometryError("attitude covariance is singular: directions are parallel")
    return np.linalg.inv(F)


# ----------------------------------------------------------------------------- from the body
@dataclass(frozen=True)
class BodyAttitude:
    """Camera attitude from one body image.

    Attributes
    ----------
    C_ci
        Estimated inertial -> camera DCM.
    covariance_rad2
        3x3 covariance of the attitude-error rotation vector (camera frame, rad^2).
    sigma_about_body_rad
        Standard deviation of the rotation about the body direction (weakly observable).
    sigma_cross_rad
        Standard deviation of the rotations about the two axes perpendicular to it.
    """

    C_ci: np.ndarray
    covariance_rad2: np.ndarray
    sigma_about_body_rad: float
    sigma_cross_rad: float


def symmetry_axis_vectors(u: np.ndarray, toward: np.ndarray) -> np.ndarray:
    """Unit vector perpendicular to ``u`` in the plane ``(u, toward)``, on the ``toward`` side."""
    u = np.asarray(u, float) / np.linalg.norm(u)
    t = np.asarray(toward, float)
    p = t - (t @ u) * u
    n = np.linalg.norm(p)
    if n < 1e-9 * max(np.linalg.norm(t), 1e-300):
        raise GeometryError(
            "symmetry axis undefined: the Sun is (anti)parallel to the body direction "
            "(phase angle 0 or 180 deg), the roll about the body direction is unobservable"
        )
    return p / n


def symmetry_axis_camera(camera, center_rc: np.ndarray, axis_angle_rad: float) -> np.ndarray:
    """Camera-frame ``b2`` from an image measurement.

    Parameters
    ----------
    camera
        :class:`~jaxlimb.geometry.camera.Camera`.
    center_rc
        Body-centre pixel ``(row, col)``.
    axis_angle_rad
        Direction of the symmetry axis in the image, pointing from the centre toward the
        lit limb, as ``atan2(d_row, d_col)``.

    The image line through the centre with direction ``(d_row, d_col)`` is lifted to the
    sphere by differentiating the LOS: ``t = dLOS/d(row,col) @ (d_row, d_col)``, then
    made perpendicular to the LOS.
    """
    J = camera.los_jacobian(np.asarray(center_rc, float))
    d = np.array([np.sin(axis_angle_rad), np.cos(axis_angle_rad)])
    u = camera.los(np.asarray(center_rc, float))
    return symmetry_axis_vectors(u, J @ d)


def attitude_from_body(
    los_center_camera: np.ndarray,
    axis_camera: np.ndarray,
    r_body_km: np.ndarray,
    r_sun_km: np.ndarray,
    r_observer_km: np.ndarray,
    sigma_center_rad: float,
    sigma_axis_rad: float,
) -> BodyAttitude:
    """Camera attitude ``C_ci`` from the body-centre LOS and the illuminated area's symmetry axis.

    Parameters
    ----------
    los_center_camera
        Direction to the body centre, camera frame.
    axis_camera
        Symmetry axis of the lit area lifted to the camera frame (perpendicular to the LOS,
        toward the lit side), e.g. from :func:`symmetry_axis_camera`.
    r_body_km, r_sun_km, r_observer_km
        Inertial positions (any common origin, km); the observer position may be rough:
        the direction to the body moves by ``|dr| / D`` rad.
    sigma_center_rad, sigma_axis_rad
        Per-axis standard deviations of the two measured directions (rad).  For the axis,
        ``sigma_axis_rad`` is the error of the axis angle in the image plane.

    Returns
    -------
    BodyAttitude
        Davenport q-method solution with weights ``1/sigma^2`` and its QUEST covariance.

    Raises
    ------
    GeometryError
        Phase angle 0 or 180 deg (no symmetry axis), non-positive sigmas.
    """
    for nm, s in (("sigma_center_rad", sigma_center_rad), ("sigma_axis_rad", sigma_axis_rad)):
        if not (np.isfinite(s) and s > 0):
            raise GeometryError(f"`{nm}` must be finite and > 0, got {s!r}")
    r1 = np.asarray(r_body_km, float) - np.asarray(r_observer_km, float)
    r1 /= np.linalg.norm(r1)
    r2 = symmetry_axis_vectors(r1, np.asarray(r_sun_km, float) - np.asarray(r_body_km, float))
    b1 = np.asarray(los_center_camera, float) / np.linalg.norm(los_center_camera)
    b2 = symmetry_axis_vectors(b1, axis_camera)
    C = davenport_q_method(np.stack([b1, b2]), np.stack([r1, r2]), np.array([sigma_center_rad**-2, sigma_axis_rad**-2]))
    P = quest_covariance(np.stack([b1, b2]), np.array([sigma_center_rad, sigma_axis_rad]))
    s_about = float(np.sqrt(b1 @ P @ b1))
    e3 = np.cross(b1, b2)
    s_cross = float(np.sqrt(0.5 * (b2 @ P @ b2 + e3 @ P @ e3)))
    return BodyAttitude(C_ci=C, covariance_rad2=P, sigma_about_body_rad=s_about, sigma_cross_rad=s_cross)


@dataclass(frozen=True)
class AttitudeAccuracy:
    """Monte-Carlo accuracy of :func:`attitude_from_body` (all angles in arcsec)."""

    n_trials: int
    rms_total_arcsec: float
    rms_about_body_arcsec: float
    rms_cross_arcsec: float
    predicted_about_body_arcsec: float
    predicted_cross_arcsec: float
    mean_nees: float


def _perturb_direction(u: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    e1 = symmetry_axis_vectors(u, np.eye(3)[int(np.argmin(np.abs(u)))])
    e2 = np.cross(u, e1)
    a, b = rng.normal(0.0, sigma, 2)
    v = u + a * e1 + b * e2
    return v / np.linalg.norm(v)


def attitude_from_body_accuracy(
    C_ci_true: np.ndarray,
    r_body_km: np.ndarray,
    r_sun_km: np.ndarray,
    r_observer_km: np.ndarray,
    sigma_center_rad: float,
    sigma_axis_rad: float,
    n_trials: int = 1000,
    seed: int = 0,
) -> AttitudeAccuracy:
    """Monte Carlo of :func:`attitude_from_body` with the two measurement noises.

    Each trial perturbs the true camera-frame body direction isotropically (per-axis
    ``sigma_center_rad``), then rotates the true symmetry axis about the *perturbed* body
    direction by ``N(0, sigma_axis_rad)`` (the image-plane axis-angle error), and solves.
    Errors are split into the rotation about the true body direction and the two
    perpendicular components.  ``mean_nees`` is the mean of ``dphi^T P^-1 dphi`` (≈ 3 if
    the QUEST covariance is consistent).
    """
    C = validate_dcm(C_ci_true, name="C_ci_true")
    rng = np.random.default_rng(seed)
    r1 = np.asarray(r_body_km, float) - np.asarray(r_observer_km, float)
    r1 /= np.linalg.norm(r1)
    r2 = symmetry_axis_vectors(r1, np.asarray(r_sun_km, float) - np.asarray(r_body_km, float))
    b1t, b2t = C @ r1, C @ r2
    errs = np.empty((n_trials, 3))
    nees = np.empty(n_trials)
    P = None
    for k in range(n_trials):
        b1 = _perturb_direction(b1t, sigma_center_rad, rng)
        b2 = symmetry_axis_vectors(b1, b2t)
        b2 = rotation_vector_to_dcm(-rng.normal(0.0, sigma_axis_rad) * b1) @ b2
        sol = attitude_from_body(b1, b2, r_body_km, r_sun_km, r_observer_km, sigma_center_rad, sigma_axis_rad)
        d = attitude_error_vector(sol.C_ci, C)
        errs[k] = d
        P = sol.covariance_rad2
        nees[k] = d @ np.linalg.solve(P, d)
    about = errs @ b1t
    cross = errs - np.outer(about, b1t)
    pred = attitude_from_body(b1t, b2t, r_body_km, r_sun_km, r_observer_km, sigma_center_rad, sigma_axis_rad)
    return AttitudeAccuracy(
        n_trials=n_trials,
        rms_total_arcsec=float(np.sqrt(np.mean(np.sum(errs**2, axis=1)))) * ARCSEC_PER_RAD,
        rms_about_body_arcsec=float(np.sqrt(np.mean(about**2))) * ARCSEC_PER_RAD,
        rms_cross_arcsec=float(np.sqrt(np.mean(np.sum(cross**2, axis=1)) / 2.0)) * ARCSEC_PER_RAD,
        predicted_about_body_arcsec=pred.sigma_about_body_rad * ARCSEC_PER_RAD,
        predicted_cross_arcsec=pred.sigma_cross_rad * ARCSEC_PER_RAD,
        mean_nees=float(np.mean(nees)),
    )


__all__ = [
    "ARCSEC_PER_RAD",
    "AttitudeAccuracy",
    "BodyAttitude",
    "attitude_error_angle",
    "attitude_error_vector",
    "attitude_from_body",
    "attitude_from_body_accuracy",
    "davenport_q_method",
    "dcm_to_quat",
    "quat_to_dcm",
    "quest_covariance",
    "rotation_vector_to_dcm",
    "skew",
    "symmetry_axis_camera",
    "symmetry_axis_vectors",
    "validate_dcm",
    "validate_quaternion",
]
