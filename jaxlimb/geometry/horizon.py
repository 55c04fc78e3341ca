r"""Christian--Robinson non-iterative horizon-based optical navigation (ellipsoid bodies).

References
----------
* J. A. Christian and S. B. Robinson, "Noniterative Horizon-Based Optical Navigation by
  Cholesky Factorization", J. Guidance, Control, and Dynamics 39(12), 2016 ("CR16").
* J. A. Christian, "Accurate Planetary Limb Localization for Image-Based Spacecraft
  Navigation", J. Spacecraft and Rockets 54(3), 2017.
* J. A. Christian, "A Tutorial on Horizon-Based Optical Navigation and Attitude
  Determination With Space Imaging Systems", IEEE Access 9, 2021,
  doi:10.1109/ACCESS.2021.3051914 (Eq. 95-119 there).
* H. Deng, H. Wang, Y. Liu, Z. Jin, "Short-Arc Horizon-Based Optical Navigation by Total
  Least-Squares Estimation", Aerospace 10(4), 371, 2023, doi:10.3390/aerospace10040371 --
  the LS solution is biased for short lit arcs; we see the same second-order bias (and the
  plain TLS below does not remove it; their element-wise TLS is not implemented).

Derivation (written out so it can be checked)
---------------------------------------------
Camera frame, camera at the origin, body centre at ``c`` (km).  With ``R`` = body->camera
rotation and ``J = diag(a^-2, b^-2, c^-2)`` the surface is ``(x - c)^T A (x - c) = 1``,
``A = R J R^T`` (the "shape matrix" in the camera frame).

1. **Whitening.**  Factor ``A = L L^T`` (Cholesky, ``L`` lower triangular) and map every
   vector by ``B = L^T``: ``x' = B x``.  Then ``(x' - c')^T (x' - c') = 1`` with ``c' = B c``:
   the body becomes the unit sphere.  (``B = Q D R^T`` for some rotation ``Q`` with
   ``D = diag(1/a, 1/b, 1/c)``; any square root of ``A`` gives the same answer, CR16 uses
   the Cholesky factor.)  Lines of sight map the same way: ``s' = B s``, a ray tangent to
   the ellipsoid becomes a ray tangent to the unit sphere (tangency is affine-invariant).
2. **Plane.**  Rays from the origin tangent to a unit sphere centred at ``c'`` form a
   circular cone of axis ``c'/|c'|`` and half-angle ``theta``, ``sin(theta) = 1/|c'|``. For a
   unit tangent direction ``sbar' = s'/|s'|``::

       sbar'^T c' = |c'| cos(theta) = sqrt(|c'|^2 - 1)
       =>  sbar'^T n = 1   with   n = c' / sqrt(c'^T c' - 1).

   So the tips of the unit limb directions lie on the plane ``n^T x = 1``: stack
   ``H = [sbar'_1^T; ...; sbar'_m^T]`` and solve ``H n = 1`` (least squares, CR16, or total
   least squares, below).
3. **Recovery.**  ``n^T n = c'^T c' / (c'^T c' - 1)`` gives ``c'^T c' - 1 = 1/(n^T n - 1)``, so
   ``c' = (n^T n - 1)^(-1/2) n`` and the **camera position relative to the body centre, in
   the camera frame**, is::

       r_c = -c = -(n^T n - 1)^(-1/2) B^-1 n = -(n^T n - 1)^(-1/2) L^-T n.

   ``n^T n > 1`` is required (else the points are not on a limb: e.g. the camera inside
   the body, or noise-only data) -> :class:`GeometryError`.

Covariance (first order, CR16 §IV)
----------------------------------
A LOS covariance ``R_s`` (3x3, rank 2, e.g. ``sigma_px^2 G G^T`` with ``G = dLOS/d(row, col)``)
maps to ``R_sbar' = P R_s P^T``, ``P = (I - sbar' sbar'^T) B / |s'|``.  The scalar residual
``y_i = sbar'_i^T n - 1`` has variance ``sigma_i^2 = n^T R_sbar'_i n``, so weighted least
squares gives ``P_n = (sum_i sbar'_i sbar'_i^T / sigma_i^2)^-1`` and with
``F = d r_c / d n = -(n^T n - 1)^(-1/2) B^-1 [I - n n^T / (n^T n - 1)]``,
``P_r = F P_n F^T``.  The estimator uses these weights (one re-weighting pass with the
unweighted ``n``), so the covariance is that of the estimator actually run.

TLS variant.  ``method="tls"`` minimises ``sum_i w_i (sbar'_i^T n - 1)^2 / (1 + n^T n)`` (the
classical TLS of ``[H | 1]`` after row weighting, via the SVD).  At the noise-free solution
the residuals vanish, so the factor ``1/(1 + n^T n)`` does not change the first-order
covariance: both methods have the ``P_r`` above; their difference is second order (measured
in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import GeometryError
from .attitude import validate_dcm


def _radii(radii) -> np.ndarray:
    try:
        r = np.asarray(radii, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError(f"`radii` must be three numbers (a, b, c) in km, got {radii!r}") from None
    if r.ndim == 0:
        r = np.full(3, float(r))
    if r.shape != (3,) or not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise GeometryError(f"`radii` must be three finite numbers > 0 (km), got {np.asarray(radii).tolist()}")
    return r


def whitening(radii, R_body_to_camera: np.ndarray) -> np.ndarray:
    """``B = L^T`` with ``L L^T = A = R J R^T`` (Cholesky of the camera-frame shape matrix)."""
    r = _radii(radii)
    R = validate_dcm(R_body_to_camera, name="R_body_to_camera")
    A = R @ np.diag(r**-2.0) @ R.T
    return np.linalg.cholesky(0.5 * (A + A.T)).T


@dataclass(frozen=True)
class HorizonSolution:
    """Result of :func:`horizon_navigation`.

    Attributes
    ----------
    r_camera_km
        Camera position relative to the body centre, **camera frame** (km): ``-body_center_camera_km``.
    body_center_camera_km
        Body-centre position in the camera frame (km).
    covariance_km2
        3x3 first-order covariance of ``r_camera_km`` (``None`` without a noise model).
    n
        The whitened plane vector (``H n = 1``).
    n_points
        Number of limb points used.
    rms_residual
        RMS of ``H n - 1`` (dimensionless).
    method
        ``"ls"`` or ``"tls"``.
    """

    r_camera_km: np.ndarray
    body_center_camera_km: np.ndarray
    covariance_km2: np.ndarray | None
    n: np.ndarray
    n_points: int
    rms_residual: float
    method: str

    @property
    def range_km(self) -> float:
        return float(np.linalg.norm(self.r_camera_km))

    @property
    def los_camera(self) -> np.ndarray:
        """Unit direction to the body centre (camera frame)."""
        return self.body_center_camera_km / np.linalg.norm(self.body_center_camera_km)

    def r_inertial_km(self, C_ci: np.ndarray) -> np.ndarray:
        """Camera position relative to the body centre in the inertial frame, ``C_ci^T r_c``."""
        return validate_dcm(C_ci).T @ self.r_camera_km

    def covariance_inertial_km2(self, C_ci: np.ndarray) -> np.ndarray | None:
        """``C_ci^T P C_ci`` (attitude error not included: add it with :func:`navigation.navigate`)."""
        if self.covariance_km2 is None:
            return None
        C = validate_dcm(C_ci)
        return C.T @ self.covariance_km2 @ C


def _solve(H: np.ndarray, w: np.ndarray, method: str) -> np.ndarray:
    sw = np.sqrt(w)
    if method == "ls":
        n, *_ = np.linalg.lstsq(H * sw[:, None], sw, rcond=None)
        return n
    Z = np.hstack([H, -np.ones((H.shape[0], 1))]) * sw[:, None]
    _, _, Vt = np.linalg.svd(Z, full_matrices=False)
    v = Vt[-1]
    if abs(v[3]) < 1e-300:
        raise GeometryError("TLS plane fit is degenerate (limb points through the origin of the whitened space)")
    return v[:3] / v[3]


def horizon_navigation(
    los_camera: np.ndarray,
    radii,
    R_body_to_camera: np.ndarray,
    *,
    los_cov: np.ndarray | None = None,
    method: Literal["ls", "tls"] = "ls",
) -> HorizonSolution:
    """Camera position from limb lines of sight (Christian--Robinson, module docstring).

    Parameters
    ----------
    los_camera
        ``(m, 3)`` directions (camera frame) of limb points; need not be unit; ``m >= 3``.
    radii
        Ellipsoid semi-axes ``(a, b, c)`` (km), or one number for a sphere.
    R_body_to_camera
        Rotation body-fixed -> camera (``C_ci @ C_ib``); validated (:class:`AttitudeError`).
    los_cov
        Optional LOS covariance of the *unit* LOS: ``(m, 3, 3)`` or ``(3, 3)`` shared (rad^2).
        Gives the weights and the covariance; see :func:`horizon_from_pixels` for pixels.
    method
        ``"ls"`` (CR16, weighted when ``los_cov`` is given) or ``"tls"``.

    Raises
    ------
    GeometryError
        Fewer than 3 points, degenerate radii, rank-deficient geometry, ``n^T n <= 1``
        (points not on a limb, e.g. camera inside the body), or the body behind the camera.
    """
    if method not in ("ls", "tls"):
        raise GeometryError(f"`method` must be 'ls' or 'tls', got {method!r}")
    s = _unit_los(los_camera)
    m = s.shape[0]
    B = whitening(radii, R_body_to_camera)
    H, nsp = _whitened_directions(s, B)
    n = _solve(H, np.ones(m), method)
    Rsb = None
    if los_cov is not None:
        Rsb = _whitened_los_cov(los_cov, H, B, nsp)
        n = _reweighted_solve(H, Rsb, n, method)

    nn, k, Binv, c = _body_center(n, B, s)
    cov = None if Rsb is None else _center_cov(n, Rsb, H, nn, k, Binv)
    res = H @ n - 1.0
    return HorizonSolution(
        r_camera_km=-c,
        body_center_camera_km=c,
        covariance_km2=cov,
        n=n,
        n_points=m,
        rms_residual=float(np.sqrt(np.mean(res**2))),
        method=method,
    )


def _whitened_directions(s: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unit lines of sight ``s`` whitened by ``B`` and normalised (``H``, ``(m, 3)``) and their norms before;
    :class:`GeometryError` when they span fewer than 3 directions."""
    sp = s @ B.T
    nsp = np.linalg.norm(sp, axis=1)
    H = sp / nsp[:, None]
    sv = np.linalg.svd(H, compute_uv=False)
    if sv[-1] < 1e-12 * sv[0]:
        raise GeometryError("limb points are degenerate (fewer than 3 independent directions)")
    return H, nsp


def _body_center(n: np.ndarray, B: np.ndarray, s: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray]:
    """``n^T n``, ``k = (n^T n - 1)^-1/2``, ``B^-1`` and the body centre ``k B^-1 n`` in the camera frame, checked
    (``n^T n > 1``, the body in front of the camera)."""
    nn = float(n @ n)
    if not nn > 1.0:
        raise GeometryError(
            f"horizon solution invalid: n^T n = {nn:.6g} <= 1 (the points are not on the limb of this body; "
            "is the camera inside the ellipsoid or are the radii/attitude wrong?)"
        )
    k = (nn - 1.0) ** -0.5
    Binv = np.linalg.inv(B)
    c = k * (Binv @ n)
    if float(np.mean(s @ c)) <= 0:
        raise GeometryError("horizon solution puts the body behind the camera; limb points inconsistent")
    return nn, k, Binv, c


def _center_cov(n: np.ndarray, Rsb: np.ndarray, H: np.ndarray, nn: float, k: float, Binv: np.ndarray) -> np.ndarray:
    """Covariance (km^2) of the body centre from the whitened LOS covariance ``Rsb``, symmetrised."""
    var = np.einsum("i,mij,j->m", n, Rsb, n)
    Pn = np.linalg.inv(np.einsum("m,mi,mj->ij", 1.0 / var, H, H))
    F = -k * Binv @ (np.eye(3) - np.outer(n, n) / (nn - 1.0))
    cov = F @ Pn @ F.T
    return 0.5 * (cov + cov.T)


def _unit_los(los_camera: np.ndarray) -> np.ndarray:
    """The ``(m, 3)`` lines of sight normalised; :class:`GeometryError` for a wrong shape, fewer than 3,
    or non-finite / zero vectors."""
    s = np.asarray(los_camera, dtype=float)
    if s.ndim != 2 or s.shape[1] != 3:
        raise GeometryError(f"`los_camera` must have shape (m, 3), got {s.shape}")
    if s.shape[0] < 3:
        raise GeometryError(f"horizon navigation needs at least 3 limb points, got {s.shape[0]}")
    if not np.all(np.isfinite(s)) or np.any(np.linalg.norm(s, axis=1) == 0):
        raise GeometryError("`los_camera` must be finite, non-zero vectors")
    return s / np.linalg.norm(s, axis=1, keepdims=True)


def _whitened_los_cov(los_cov: np.ndarray, H: np.ndarray, B: np.ndarray, nsp: np.ndarray) -> np.ndarray:
    """The covariance of each unit LOS carried to the whitened, normalised direction ``h_i`` (``(m, 3, 3)``)."""
    m = H.shape[0]
    Rs = np.asarray(los_cov, dtype=float)
    if Rs.shape == (3, 3):
        Rs = np.broadcast_to(Rs, (m, 3, 3))
    if Rs.shape != (m, 3, 3) or not np.all(np.isfinite(Rs)):
        raise GeometryError(f"`los_cov` must have shape (3, 3) or ({m}, 3, 3), got {np.asarray(los_cov).shape}")
    Pm = (np.eye(3)[None] - H[:, :, None] * H[:, None, :]) @ B[None] / nsp[:, None, None]
    return Pm @ Rs @ np.transpose(Pm, (0, 2, 1))


def _reweighted_solve(H: np.ndarray, Rsb: np.ndarray, n: np.ndarray, method: str) -> np.ndarray:
    """Two re-weightings of the solve with the residual variances ``n^T R_i n`` of the current ``n``."""
    for _ in range(2):  # the weights depend on n only weakly
        var = np.einsum("i,mij,j->m", n, Rsb, n)
        if np.any(var <= 0):
            raise GeometryError("`los_cov` gives a zero variance along a residual; it must be positive definite across the LOS")
        w = 1.0 / var
        n = _solve(H, w / w.mean(), method)
    return n


def horizon_from_pixels(
    camera,
    limb_rc: np.ndarray,
    radii,
    R_body_to_camera: np.ndarray,
    *,
    sigma_px: float | np.ndarray | None = None,
    method: Literal["ls", "tls"] = "ls",
) -> HorizonSolution:
    """:func:`horizon_navigation` from limb pixels ``(m, 2)`` ``(row, col)`` (distortion handled).

    ``sigma_px`` is the per-axis pixel noise (scalar, or ``(m,)`` per point, or ``(m, 2, 2)``
    pixel covariances); it is mapped to LOS covariances with the camera's LOS Jacobian.
    """
    rc = np.asarray(limb_rc, dtype=float)
    if rc.ndim != 2 or rc.shape[1] != 2:
        raise GeometryError(f"`limb_rc` must have shape (m, 2), got {rc.shape}")
    s = camera.los(rc)
    cov = None
    if sigma_px is not None:
        sp = np.asarray(sigma_px, dtype=float)
        if sp.ndim == 0:
            Ppx = np.broadcast_to(float(sp) ** 2 * np.eye(2), (rc.shape[0], 2, 2))
        elif sp.shape == (rc.shape[0],):
            Ppx = sp[:, None, None] ** 2 * np.eye(2)[None]
        elif sp.shape == (rc.shape[0], 2, 2):
            Ppx = sp
        else:
            raise GeometryError(f"`sigma_px` must be a scalar, (m,) or (m, 2, 2), got shape {sp.shape}")
        G = camera.los_jacobian(rc)
        cov = G @ Ppx @ np.transpose(G, (0, 2, 1))
    return horizon_navigation(s, radii, R_body_to_camera, los_cov=cov, method=method)


def limb_directions(radii, r_camera_body_km: np.ndarray, R_body_to_camera: np.ndarray, n: int, arc: tuple[float, float] = (0.0, 2 * np.pi)) -> np.ndarray:
    """Exact limb (tangent-ray) directions, camera frame, ``(n, 3)`` unit vectors.

    Independent of the whitening used by the estimator: for the cone matrix
    ``M = J p p^T J - (p^T J p - 1) J`` (Mortari et al. Eq. 2, body frame, ``p`` = camera
    position relative to the body) with cone axis ``w3`` (eigenvector of the positive
    eigenvalue) and the two other eigenvectors ``w1, w2``, each ray
    ``v = w3 + t (cos(phi) w1 + sin(phi) w2)`` is tangent for the positive root of
    ``v^T M v = 0``, i.e. ``t^2 = -lambda3 / (lambda1 cos^2 phi + lambda2 sin^2 phi)``.

    Parameters
    ----------
    r_camera_body_km
        Camera position relative to the body centre, **body frame** (km).
    arc
        Range of the angle ``phi`` around the cone axis (a partial limb for a crescent).

    Raises
    ------
    GeometryError
        Degenerate radii or the camera inside/on the ellipsoid (``p^T J p <= 1``).
    """
    r = _radii(radii)
    p = np.asarray(r_camera_body_km, dtype=float)
    R = validate_dcm(R_body_to_camera, name="R_body_to_camera")
    J = np.diag(r**-2.0)
    g = float(p @ J @ p)
    if not g > 1.0:
        raise GeometryError(f"camera must be outside the ellipsoid (p^T J p > 1), got p^T J p = {g:.6g} for p = {p.tolist()} km")
    M = J @ np.outer(p, p) @ J - (g - 1.0) * J
    lam, V = np.linalg.eigh(0.5 * (M + M.T))
    w1, w2, w3 = V[:, 0], V[:, 1], V[:, 2]
    if w3 @ (-p) < 0:
        w3 = -w3
    phi = np.linspace(arc[0], arc[1], n, endpoint=(arc[1] - arc[0]) < 2 * np.pi - 1e-12)
    t = np.sqrt(-lam[2] / (lam[0] * np.cos(phi) ** 2 + lam[1] * np.sin(phi) ** 2))
    v = w3[None] + t[:, None] * (np.cos(phi)[:, None] * w1 + np.sin(phi)[:, None] * w2)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v @ R.T


@dataclass(frozen=True)
class HorizonMonteCarlo:
    """Monte-Carlo consistency of :func:`horizon_from_pixels` (see :func:`horizon_monte_carlo`)."""

    n_trials: int
    mean_nees: float
    bias_km: np.ndarray
    rms_error_km: np.ndarray
    predicted_sigma_km: np.ndarray


def horizon_monte_carlo(
    camera,
    radii,
    r_camera_body_km: np.ndarray,
    R_body_to_camera: np.ndarray,
    *,
    n_points: int,
    sigma_px: float,
    n_trials: int,
    seed: int,
    arc: tuple[float, float] = (0.0, 2 * np.pi),
    method: Literal["ls", "tls"] = "ls",
) -> HorizonMonteCarlo:
    """Add Gaussian pixel noise to exact limb points, solve, compare to the covariance.

    ``mean_nees`` is the mean of ``e^T P^-1 e`` (``e`` = estimate - truth in the camera frame):
    ≈ 3 when the first-order covariance is right.
    """
    rng = np.random.default_rng(seed)
    R = validate_dcm(R_body_to_camera, name="R_body_to_camera")
    v = limb_directions(radii, r_camera_body_km, R, n_points, arc)
    rc0 = camera.project(v)
    truth = R @ np.asarray(r_camera_body_km, dtype=float)
    errs = np.empty((n_trials, 3))
    nees = np.empty(n_trials)
    sig = None
    for k in range(n_trials):
        sol = horizon_from_pixels(camera, rc0 + sigma_px * rng.standard_normal(rc0.shape), radii, R, sigma_px=sigma_px, method=method)
        e = sol.r_camera_km - truth
        errs[k] = e
        nees[k] = e @ np.linalg.solve(sol.covariance_km2, e)
        sig = np.sqrt(np.diag(sol.covariance_km2))
    return HorizonMonteCarlo(
        n_trials=n_trials,
        mean_nees=float(nees.mean()),
        bias_km=errs.mean(axis=0),
        rms_error_km=np.sqrt((errs**2).mean(axis=0)),
        predicted_sigma_km=sig,
    )


__all__ = [
    "HorizonMonteCarlo",
    "HorizonSolution",
    "horizon_from_pixels",
    "horizon_monte_carlo",
    "horizon_navigation",
    "limb_directions",
    "whitening",
]
