"""The physical profile's weighted system (Jacobian and residuals at an estimate, one compiled program per model) and
the model-error terms it widens a fit's covariance with (:mod:`jaxlimb.model_error`): the cluster-robust
sandwich over sectors of the limb, the split witness (Hausman 1978) and an unknown albedo field's consider term
(:mod:`~jaxlimb.pipeline.profile.albedo_prior`); the one-step score estimates of the widening gates."""

from __future__ import annotations

import math
from typing import Any

import jax
import numpy as np

from ..._programs import stored_jit
from ...model_error import cluster_robust_covariance, hausman_term, sector_groups, with_model_error as widen
from ...geometry.conic import ellipse_signed_distance
from ...models import CircleParams, EllipseRampParams, LimbDarkenedParams, LimbModel, LimbProfileParams
from ...models.corona import CoronaParams
from ...models.lunar_lambert import limb_geometry, profile_model
from ..sigmoid import LOGISTIC_TO_GAUSS, columns, pad_coords
from ..stages import RefineResult
from .albedo_prior import albedo_consider, with_albedo_term


MODEL_ERROR_SECTORS = 24
"""Angular sectors of the cluster-robust model-error term (:func:`with_model_error`)."""


WITNESS_CUT: tuple[float, ...] = (1.0, 2.0)
"""The splits of :func:`split_witness`: for each ``c``, the pixels outside ``-c`` effective PSF sigmas of the
limb (the sky side and the edge) and those inside ``+c`` (the edge and the disc).  Two cuts see a model error
that lives at one depth of the profile (a glow, a rim) better than one; tuned on the project's scene families
(``docs/validation/constants.md#witness_cut``)."""


_GEOMETRIC = ("r0", "c0", "a", "theta", "rho")


@stored_jit
def _signed_profile(p, rc):
    g = limb_geometry(p, rc)
    return g[4] - g[6]


def signed_distance(params: Any, coords: np.ndarray, padded: np.ndarray) -> np.ndarray:
    """Signed distance (px, positive outside) of the pixels to the fitted limb: the profile's own radius in each
    pixel's direction; the ellipse (first order) of an elliptical sigmoid/ramp; the circle's (the limb-darkened
    disc's and the EUV corona's) radius.

    Parameters
    ----------
    params : LimbProfileParams, EllipseParams, EllipseRampParams, CircleParams or LimbDarkenedParams
        The fitted parameters.
    coords : np.ndarray (n, 2)
        The pixels ``(row, col)``.
    padded : jax.Array (m, 2)
        ``coords`` padded to its bucket (the profile's compiled program; :func:`weighted_system`).

    Returns
    -------
    np.ndarray (n,)
        The distances (px).
    """
    if isinstance(params, LimbProfileParams):
        return np.asarray(_signed_profile(params, padded))[: coords.shape[0]]
    c = np.asarray(coords, float)
    if isinstance(params, (LimbDarkenedParams, CoronaParams)):
        return np.hypot(c[:, 0] - float(params.r0), c[:, 1] - float(params.c0)) - float(params.a)
    if not isinstance(params, CircleParams):  # an elliptical sigmoid or ramp
        a = float(params.a)
        ell = ((float(params.r0), float(params.c0)), (a, a * float(params.rho)), float(params.theta))
        return ellipse_signed_distance(c, ell)
    return np.hypot(c[:, 0] - float(params.r0), c[:, 1] - float(params.c0)) - float(params.radius)


def edge_sigma(params: Any) -> float:
    """The effective (pixel box included) Gaussian sigma of the fitted edge: ``sqrt(sigma^2 + 1/12)`` for the
    profile and the limb-darkened disc, ``1/k`` for the ramp's kernel, ``LOGISTIC_TO_GAUSS / k`` for a logistic.

    Parameters
    ----------
    params : LimbProfileParams, LimbDarkenedParams, EllipseRampParams, CircleParams or EllipseParams
        The fitted parameters.

    Returns
    -------
    float
        The sigma (px).
    """
    if isinstance(params, (LimbProfileParams, LimbDarkenedParams, CoronaParams)):
        return math.sqrt(float(params.sigma) ** 2 + 1.0 / 12.0)
    k = abs(float(params.k))
    return (1.0 if isinstance(params, EllipseRampParams) else LOGISTIC_TO_GAUSS) / max(k, 1e-6)


def with_model_error(rr: RefineResult, n_sectors: int = MODEL_ERROR_SECTORS, model: LimbModel | None = None,
                     system=None, consider: bool = True) -> RefineResult:
    """``rr`` (a fit of ``model``, default the profile) with its covariance widened by the model-error terms
    of :mod:`jaxlimb.model_error`: the cluster-robust term over ``n_sectors`` sectors of the limb
    about the fitted centre, plus the split witness (:func:`split_witness`) on the limb's geometry, and for the
    physical profile an unknown albedo field's consider term where those two do not already carry it
    (:mod:`~jaxlimb.pipeline.profile.albedo_prior`).  The noise-only covariance is kept as ``noise_covariance`` (the
    Cramér--Rao bound's).  Level-normalised data (weights): the weighted residuals and Jacobian, as the fit minimises
    them.

    Why: an albedo that varies along and across the limb (maria, clouds), another reflectance law, a glow or a
    PSF of another shape bias the centre by more than the noise-only sigma, in a pattern that varies along the limb
    (the sector term sees it).  A misfit the same all along the limb (Minnaert's limb brightening) leaves no sector
    structure; the split witness sees it.  An albedo that darkens toward the limb in one part of it leaves no
    residual at all (to the pixels there it is the edge moved); the consider term takes its amplitude from what of
    the residuals varies along the limb.

    Parameters
    ----------
    rr : RefineResult
        The fit.
    n_sectors : int
        Angular sectors of the cluster-robust term.
    model : LimbModel or None
        ``rr``'s model (``None``: the profile of its parameters).
    system : tuple or None
        ``rr``'s :func:`weighted_system` under ``model``, if already formed.
    consider : bool
        Whether to add the albedo's consider term (not for a fit whose covariance already holds the field:
        :func:`~jaxlimb.pipeline.profile.albedo_field.with_albedo_field`).

    Returns
    -------
    RefineResult
        ``rr`` with the widened covariance and ``noise_covariance`` the fit's own.
    """

    model = profile_model(rr.fit.params) if model is None else model
    fit = rr.fit
    coords = np.asarray(rr.data.coords, float)
    J, r, padded, w = weighted_system(rr, model) if system is None else system
    groups = sector_groups(coords, (float(fit.params.r0), float(fit.params.c0)), n_sectors)
    C0 = np.asarray(fit.covariance)
    C = widen(C0, cluster_robust_covariance(J, r, groups))
    s = signed_distance(fit.params, coords, padded)
    idx, W = split_witness(rr, J, r, s)
    C[np.ix_(idx, idx)] += W
    if consider and isinstance(fit.params, LimbProfileParams):
        C = with_consider_term(C, C0, albedo_consider(fit.params, coords, J, r, w, s)[0], idx)
    return rr.with_covariance(C, noise_covariance=C0)


def with_consider_term(C: np.ndarray, C0: np.ndarray, Ca: np.ndarray, idx: list[int]) -> np.ndarray:
    """``C`` widened by the albedo's consider term ``Ca`` where its model-error terms do not already carry it
    (:func:`~jaxlimb.pipeline.profile.albedo_prior.with_albedo_term`), on the limb's geometry only (as the split
    witness): the reflectance law's parameters keep their sigma, and with it the band ``L`` is held to.

    Parameters
    ----------
    C, C0, Ca : np.ndarray (q, q)
        The covariance with its model-error terms, the noise-only one and the consider term, over the free parameters.
    idx : list of int
        The geometric parameters' indices among them (:func:`split_witness`).

    Returns
    -------
    np.ndarray (q, q)
    """
    C = np.array(C)
    g = np.ix_(idx, idx)
    C[g] = with_albedo_term(C[g], C0[g], Ca[g])
    return C


def weighted_system(rr: RefineResult, model: LimbModel):
    """The weighted Jacobian (free parameters of ``rr.fit``) and residuals of ``rr`` under ``model``, the padded
    device coordinates (one program per bucket) and the pixel weights.

    Parameters
    ----------
    rr : RefineResult
        The fit and its data.
    model : LimbModel
        The model evaluated at ``rr.fit.params``.

    Returns
    -------
    J : np.ndarray (n, p)
        Weighted Jacobian by the ``p`` free parameters.
    r : np.ndarray (n,)
        Weighted residuals (data minus model).
    padded : jax.Array (m, 2)
        The pixels padded to their bucket.
    w : np.ndarray (n,)
        The pixel weights (ones without level normalisation).
    """

    fit = rr.fit
    coords = np.asarray(rr.data.coords, float)
    n = coords.shape[0]
    padded = jax.device_put(pad_coords(coords))  # no recompiles; host data: no identity program per shape
    f, cols = columns(model)(fit.params, padded)
    names = model.param_names
    w = np.ones(n) if rr.data.weights is None else np.asarray(rr.data.weights, float)
    J = np.stack([np.asarray(cols[names.index(k)])[:n] for k in fit.free], axis=1) * w[:, None]
    r = (np.asarray(rr.data.z, float) - np.asarray(f)[:n]) * w
    return J, r, padded, w


def split_witness(rr: RefineResult, J: np.ndarray, r: np.ndarray, s: np.ndarray) -> tuple[list[int], np.ndarray]:
    """The specification-test term of :mod:`jaxlimb.model_error` (Hausman 1978) on the limb's geometry (the free
    ones of ``r0, c0, a, theta, rho``): the profile refitted on the sky side and the edge (signed distance ``s`` to
    the limb above ``-c`` effective PSF sigmas) and on the edge and the disc (below ``+c``), ``c`` in
    :data:`WITNESS_CUT`; the sum of ``[d d^T - (C_sub - C)]_+`` over the subsets.  Each refit is one Gauss--Newton
    step from the full fit's answer with its Jacobian ``J`` and residuals ``r`` (no new model evaluation; the step
    is the subset fit to first order).  A subset of fewer than 50 pixels (or all of them) contributes nothing.

    Parameters
    ----------
    rr : RefineResult
        The fit.
    J : np.ndarray (n, p)
        Its weighted Jacobian (:func:`weighted_system`).
    r : np.ndarray (n,)
        Its weighted residuals.
    s : np.ndarray (n,)
        Signed distance (px) of the pixels to the fitted limb (:func:`signed_distance`).

    Returns
    -------
    idx : list of int
        Indices of the geometric parameters among ``rr.fit.free``.
    W : np.ndarray (k, k)
        The term, on those parameters.
    """

    fit = rr.fit
    free = list(fit.free)
    idx = [free.index(nm) for nm in _GEOMETRIC if nm in free]
    W = np.zeros((len(idx), len(idx)))
    C = np.asarray(fit.covariance)[np.ix_(idx, idx)]
    se = edge_sigma(fit.params)
    q = J.shape[1]
    for keep in [m for c in WITNESS_CUT for m in (s > -c * se, s < c * se)]:
        nk = int(np.count_nonzero(keep))
        if nk < max(50, 2 * q) or nk == s.size:
            continue
        Jk, rk = J[keep], r[keep]
        A_inv = np.linalg.pinv(Jk.T @ Jk)
        step = A_inv @ (Jk.T @ rk)
        s2 = float(np.sum((rk - Jk @ step) ** 2)) / (nk - q)
        W += hausman_term(step[idx], s2 * A_inv[np.ix_(idx, idx)], C)
    return idx, W


def last_step(X: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """The last component of the least-squares step ``X^+ r`` and its z-score: a one-step score estimate of the
    last column's coefficient.

    Parameters
    ----------
    X : np.ndarray (n, p)
        The weighted Jacobian with the tested column last.
    r : np.ndarray (n,)
        The weighted residuals.

    Returns
    -------
    tuple of float
        ``(step, z)``; ``(0, 0)`` with fewer than ``max(50, 2 p)`` rows.
    """
    if X.shape[0] < max(50, 2 * X.shape[1]):
        return 0.0, 0.0
    step, var = last_column_step(X, r)
    return step, step / math.sqrt(max(var, 1e-300))


def trailing_step(X: np.ndarray, r: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The last ``k`` components of the least-squares step ``X^+ r`` (the last ``k`` columns' coefficients with the
    others fitted beside them) and their covariance from the residual scatter (``s^2 [(X^T X)^-1]``'s trailing
    block).

    Parameters
    ----------
    X : np.ndarray (n, p)
        The weighted Jacobian with the tested columns last.
    r : np.ndarray (n,)
        The weighted residuals.
    k : int
        Number of trailing columns.

    Returns
    -------
    step : np.ndarray (k,)
        Their coefficients.
    cov : np.ndarray (k, k)
        Their covariance.
    """
    A_inv = np.linalg.pinv(X.T @ X)
    step = A_inv @ (X.T @ r)
    s2 = float(np.sum((r - X @ step) ** 2)) / max(X.shape[0] - X.shape[1], 1)
    return step[-k:], s2 * A_inv[-k:, -k:]


def last_column_step(X: np.ndarray, r: np.ndarray) -> tuple[float, float]:
    """:func:`trailing_step` of the last column alone: its coefficient and its variance.

    Parameters
    ----------
    X : np.ndarray (n, p)
        The weighted Jacobian with the tested column last.
    r : np.ndarray (n,)
        The weighted residuals.

    Returns
    -------
    tuple of float
        ``(step, variance)``.
    """
    step, var = trailing_step(X, r, 1)
    return float(step[0]), float(var[0, 0])


__all__ = ["MODEL_ERROR_SECTORS", "WITNESS_CUT", "columns", "edge_sigma", "last_column_step", "last_step", "signed_distance", "split_witness", "trailing_step", "weighted_system", "with_consider_term",
           "with_model_error"]
