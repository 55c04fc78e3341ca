r"""The profile refitted with the surface albedo as an unknown Gaussian field, marginalised
(``LocateOptions(profile="albedo-field")``).

The one-albedo profile reads an albedo that changes across the few pixels inside the limb as a moved edge.  Here the
relative albedo is a zero-mean Gaussian field on the sphere (:mod:`jaxlimb.models.profile_columns`: columns ``K``,
prior ``tau^2 C_ell``), so the pixels' covariance is ``Sigma = s^2 I + tau^2 K C_ell K^T`` and the profile's
parameters are the generalised least-squares fit under ``Sigma``, with the covariance ``(J^T Sigma^-1 J)^-1``: the
Bayesian Cramér--Rao bound with the albedo unknown (Van Trees 1968, Sec. 2.4).

Nothing about the albedo is assumed beyond a smooth field: its amplitude ``tau``, the noise ``s`` and the correlation
length ``ell`` (of :data:`ELL_DEG`) are those of largest marginal likelihood of the one-albedo fit's residuals
(type-II maximum likelihood, Rasmussen & Williams 2006, Sec. 5.4).  With ``U = K C_ell^{1/2} = Q S V^T`` (thin
SVD), ``Sigma`` has eigenvalues ``s^2 + tau^2 S_j^2`` on ``Q`` and ``s^2`` elsewhere, so the likelihood costs ``O(m)``
per evaluation and the whitened residual is ``(r - Q (d * Q^T r)) / s``, ``d = 1 - s / sqrt(s^2 + tau^2 S^2)``.  A
uniform albedo gives ``tau`` near 0 and the one-albedo answer back.
"""

from __future__ import annotations

import math
from dataclasses import replace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ...fitting import bucket_size
from ...geometry.sphere_image import sphere_from_ellipse_center
from ...models import LimbProfileParams, limb_profile_intensity
from ...models.profile_columns import albedo_field_factor
from ..stages import Frame, RefineResult
from .model_error import with_model_error

ELL_DEG = (8.0, 16.0, 32.0)
"""Correlation lengths (deg on the surface) among which the marginal likelihood chooses: a factor of two apart,
from features about the PSF's width in surface angle at a 30-80 px limb (``sqrt(2 sigma / R)``, 8-14 deg) to
hemispheric gradients."""


def field_basis(p: LimbProfileParams, coords: np.ndarray, ell_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """``Q, S`` of the thin SVD of ``K C_ell^{1/2}`` (module docstring) at the profile ``p``.

    Parameters
    ----------
    p : LimbProfileParams
        The profile.
    coords : np.ndarray (n, 2)
        Its pixels.
    ell_rad : float
        Correlation length (rad).

    Returns
    -------
    Q : np.ndarray (n, m)
    S : np.ndarray (m,)
    """
    Q, S, _ = np.linalg.svd(albedo_field_factor(p, coords, 1.0, ell_rad), full_matrices=False)
    return Q, S


def field_likelihood(r: np.ndarray, Q: np.ndarray, S: np.ndarray) -> tuple[float, float, float]:
    """Type-II maximum likelihood of the noise variance and the albedo field's amplitude for residuals ``r``.

    Parameters
    ----------
    r : np.ndarray (n,)
        Residuals of the one-albedo fit (DN).
    Q, S : np.ndarray
        :func:`field_basis`.

    Returns
    -------
    tuple of float
        ``(s2, tau2, nll)``: the noise variance (DN^2), the field's variance and the negative log marginal
        likelihood (up to a constant).
    """
    from scipy.optimize import minimize  # imported on first use: not on locate's default path

    y2, rr, n = (Q.T @ r) ** 2, float(r @ r), r.size
    S2 = S * S

    def nll(x):
        s2, t2 = math.exp(x[0]), math.exp(x[1])
        lam = s2 + t2 * S2
        return 0.5 * ((rr - y2.sum()) / s2 + np.sum(y2 / lam) + (n - S.size) * x[0] + np.sum(np.log(lam)))

    s0 = rr / n
    best = min((minimize(nll, [math.log(s0 * f), math.log(t)], method="Nelder-Mead",
                         options={"xatol": 1e-4, "fatol": 1e-6}) for f in (0.1, 1.0) for t in (1e-4, 1e-2)),
               key=lambda o: o.fun)
    return math.exp(best.x[0]), math.exp(best.x[1]), float(best.fun)


@eqx.filter_jit
def _solve(p: LimbProfileParams, free: tuple[str, ...], coords, z, mask, Q, d, s):
    """The generalised least-squares fit from ``p`` (``free`` varied) under ``Sigma`` (``Q, d, s``: module docstring);
    padded pixels (``mask`` 0) and basis columns (``d`` 0) add nothing.  Its parameters' vector, the whitened
    Jacobian there and whether the solver converged."""
    import optimistix as optx  # imported on first use: not on locate's default path

    def fn(x, _args):
        q = p.replace(**{n: x[i] for i, n in enumerate(free)})
        r = mask * (z - limb_profile_intensity(q, coords))
        return (r - Q @ (d * (Q.T @ r))) / s

    x0 = jnp.stack([jnp.asarray(getattr(p, n), float) for n in free])
    sol = optx.least_squares(fn, optx.LevenbergMarquardt(rtol=1e-10, atol=1e-9), x0, max_steps=200, throw=False)
    return sol.value, jax.jacfwd(lambda v: fn(v, None))(sol.value), sol.result == optx.RESULTS.successful


def _gls_pass(p: LimbProfileParams, free, coords, z, Q, S, s2, t2):
    """One generalised least-squares fit from ``p`` under ``Sigma`` (held), on pixels and basis padded to buckets (one
    program per bucket); its parameters and covariance."""
    n, m = Q.shape
    N, M = bucket_size(n), bucket_size(m)

    def pad(a, rows, cols=None):
        return np.pad(a, ((0, rows - a.shape[0]),) + (((0, cols - a.shape[1]),) if cols else ()))

    rc = np.concatenate([coords, np.repeat(coords[:1], N - n, axis=0)])
    s = math.sqrt(s2)
    d = pad(1.0 - s / np.sqrt(s2 + t2 * S * S), M)
    arrays = jax.tree_util.tree_map(lambda v: jnp.asarray(v, float), p)  # traced, not static: one program per bucket
    x, J, ok = _solve(arrays, tuple(free), jnp.asarray(rc), jnp.asarray(pad(z, N)), jnp.asarray(pad(np.ones(n), N)),
                      jnp.asarray(pad(Q, N, M)), jnp.asarray(d), jnp.asarray(s))
    J = np.asarray(J)
    q = p.replace(**{k: float(x[i]) for i, k in enumerate(free)})
    return q, np.linalg.inv(J.T @ J), bool(ok)


def albedo_field_refit(frame: Frame, rr: RefineResult) -> RefineResult:
    """``rr`` (a one-albedo profile fit) refitted with the albedo as a marginalised Gaussian field (module docstring);
    ``rr`` with its model-error terms (:func:`~jaxlimb.pipeline.profile.model_error.with_model_error`) when its
    profile is a widened variant, its data are weighted or the refit fails.

    Parameters
    ----------
    frame : Frame
        The frame (its camera sets the sphere's image shape).
    rr : RefineResult
        The one-albedo fit of :data:`~jaxlimb.models.LIMB_PROFILE`, unweighted.

    Returns
    -------
    RefineResult
        The refit, its covariance the field's; ``noise_covariance`` the one-albedo fit's noise-only covariance.
    """
    p = rr.fit.params
    if type(p) is not LimbProfileParams or rr.data.weights is not None:
        return with_model_error(rr)
    coords, z = np.asarray(rr.data.coords, float), np.asarray(rr.data.z, float)
    r = z - np.asarray(limb_profile_intensity(p, jnp.asarray(coords)))
    bases = [field_basis(p, coords, math.radians(e)) for e in ELL_DEG]
    (Q, S), (s2, t2, _) = min(((b, field_likelihood(r, *b)) for b in bases), key=lambda f: f[1][2])
    q, C, ok = _gls_pass(p, rr.fit.free, coords, z, Q, S, s2, t2)
    sph = rr.sphere
    if ok and frame.use_camera:
        sph = sphere_from_ellipse_center(frame.cam.focal_px, frame.cam.principal_point_rc, (float(q.r0), float(q.c0)),
                                         float(q.a))
        q, C, ok = _gls_pass(q.replace(theta=float(sph.angle_rad), rho=float(sph.rho)), rr.fit.free, coords, z, Q, S,
                             s2, t2)
    if not ok or not np.all(np.isfinite(C)):
        return with_model_error(rr)
    fit = eqx.tree_at(lambda f: (f.params, f.covariance, f.sigma2), rr.fit, (q, jnp.asarray(C), jnp.asarray(s2)))
    return replace(rr, fit=fit, sphere=sph, noise_covariance=np.asarray(rr.covariance_noise))


__all__ = ["ELL_DEG", "albedo_field_refit", "field_basis", "field_likelihood"]
