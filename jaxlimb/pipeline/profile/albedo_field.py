r"""The profile refitted with the surface albedo as an unknown Gaussian field, marginalised
(``LocateOptions(profile="albedo-field")``).

The one-albedo profile reads an albedo that changes across the few pixels inside the limb as a moved edge.  Here the
relative albedo is a zero-mean Gaussian field on the sphere (:mod:`jaxlimb.models.profile_columns`: columns ``K``,
prior ``tau^2 C_ell``), so the pixels' covariance is ``Sigma = s^2 I + tau^2 K C_ell K^T`` and the profile's
parameters are the generalised least-squares fit under ``Sigma``, with the covariance ``(J^T Sigma^-1 J)^-1``: the
Bayesian Cramér--Rao bound with the albedo unknown (Van Trees 1968, Sec. 2.4).

Nothing about the albedo is assumed beyond a smooth field: its amplitude ``tau``, the noise ``s`` and the correlation
length ``ell`` are those of largest marginal likelihood of the one-albedo fit's residuals
(:func:`~jaxlimb.pipeline.profile.albedo_prior.field_likelihood`), under the field's columns as those residuals see
them (:func:`restricted`).  With ``U = K C_ell^{1/2} = Q S V^T`` (thin
SVD), ``Sigma`` has eigenvalues ``s^2 + tau^2 S_j^2`` on ``Q`` and ``s^2`` elsewhere, so the likelihood costs ``O(m)``
per evaluation and the whitened residual is ``(r - Q (d * Q^T r)) / s``, ``d = 1 - s / sqrt(s^2 + tau^2 S^2)``.  A
uniform albedo gives ``tau`` near 0 and the one-albedo answer back.

The profile under the field is the one the widening chain chose (limb brightening, a glow, a smear), or the
unwidened one when that explains the pixels better with the field (:func:`albedo_field_refit`): an albedo that darkens
toward the limb reads as limb brightening to a one-albedo fit.  The fit itself is Gauss--Newton on the whitened system
with the model's analytic columns; its covariance is the field's, widened by what the field did not explain.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ...geometry.sphere_image import sphere_from_ellipse_center
from ...model_error import cluster_robust_covariance, sector_groups, with_model_error as widen
from ...models import LimbModel, LimbProfileParams, MinnaertProfileParams
from ...models.lunar_lambert import profile_model
from ...numerics import one_blas_thread
from ..stages import Frame, RefineResult
from .albedo_prior import ELL_DEG, field_factor, field_likelihood, residual_field, thin_svd
from .model_error import (MODEL_ERROR_SECTORS, signed_distance, split_witness, weighted_system, with_consider_term,
                          with_model_error)
from .passes import l_band


ShapeRule = Callable[[Frame, RefineResult, LimbProfileParams], RefineResult]
"""How a body strategy's limb shape follows the profile's parameters in the refit (:func:`sphere_shape`,
:func:`held_shape`)."""


def field_basis(p: LimbProfileParams, coords: np.ndarray, ell_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """The field's basis: the thin SVD (:func:`~jaxlimb.pipeline.profile.albedo_prior.thin_svd`) of its columns
    (:func:`~jaxlimb.pipeline.profile.albedo_prior.field_factor`).

    Parameters
    ----------
    p, coords, ell_rad
        The profile, its pixels ``(n, 2)`` and the field's correlation length (rad), as ``field_factor``'s.

    Returns
    -------
    tuple of np.ndarray
        ``Q`` ``(n, m)`` with orthonormal columns and the singular values ``S`` ``(m,)``.
    """
    return thin_svd(field_factor(p, coords, ell_rad))


def _whiten(A: np.ndarray, Q: np.ndarray, d: np.ndarray, s: float) -> np.ndarray:
    """``Sigma^{-1/2} A`` for residuals or Jacobian columns ``A`` (module docstring)."""
    return (A - Q @ (d[:, None] * (Q.T @ A) if A.ndim == 2 else d * (Q.T @ A))) / s


def sphere_shape(frame: Frame, rr: RefineResult, q: LimbProfileParams) -> RefineResult:
    """``rr`` with the parameters ``q``; with a camera and a held shape, the sphere's ellipse shape follows the centre
    (as :func:`~jaxlimb.pipeline.profile.passes.profile_passes` holds it): the sphere strategy's shape rule.

    Parameters
    ----------
    frame : Frame
        The frame (its camera).
    rr : RefineResult
        The fit being moved.
    q : LimbProfileParams
        Its new parameters.

    Returns
    -------
    RefineResult
        ``rr`` at ``q``, ``theta, rho`` and the sphere's image those of the centre.
    """
    sph = rr.sphere
    if frame.use_camera and "theta" not in rr.fit.free:
        sph = sphere_from_ellipse_center(frame.cam.focal_px, frame.cam.principal_point_rc, (float(q.r0), float(q.c0)),
                                         float(q.a))
        q = q.replace(theta=float(sph.angle_rad), rho=float(sph.rho))
    return replace(held_shape(frame, rr, q), sphere=sph)


def held_shape(frame: Frame, rr: RefineResult, q: LimbProfileParams) -> RefineResult:  # noqa: ARG001
    """``rr`` with the parameters ``q``, the shape ``theta, rho`` as the fit holds it: the ellipsoid strategy's rule
    (its shape is the spheroid's image, predicted again after the fit,
    :mod:`jaxlimb.pipeline.ellipsoid.profile`).

    Parameters
    ----------
    frame : Frame
        Unused (the rule's signature).
    rr : RefineResult
        The fit being moved.
    q : LimbProfileParams
        Its new parameters.

    Returns
    -------
    RefineResult
        ``rr`` at ``q``.
    """
    return replace(rr, fit=eqx.tree_at(lambda f: f.params, rr.fit, q))


def _moved(frame: Frame, rr: RefineResult, x: np.ndarray, shape: ShapeRule) -> RefineResult:
    """``rr`` with its free parameters at ``x``, its shape by ``shape``."""
    return shape(frame, rr, rr.fit.params.replace(**{k: float(x[i]) for i, k in enumerate(rr.fit.free)}))


def gls_refit(frame: Frame, rr: RefineResult, model: LimbModel, Q, S, s2: float, t2: float, max_iter: int = 30,
              system=None, shape: ShapeRule = sphere_shape):
    """The generalised least-squares fit under ``Sigma`` (``Q, S, s2, t2``: module docstring) from ``rr``, by
    Gauss--Newton steps on the whitened system (each halved until the whitened cost does not rise) with the model's
    own analytic columns (:func:`~jaxlimb.pipeline.profile.model_error.weighted_system`: no program of its own).

    Parameters
    ----------
    frame : Frame
        The frame (its camera sets the sphere's image shape).
    rr : RefineResult
        The start: an unweighted fit of ``model``.
    model : LimbModel
        The profile model.
    Q, S : np.ndarray
        :func:`field_basis`.
    s2, t2 : float
        The noise variance and the field's variance (:func:`~jaxlimb.pipeline.profile.albedo_prior.field_likelihood`).
    max_iter : int
        Gauss--Newton steps at most.
    system : tuple or None
        ``rr``'s :func:`~jaxlimb.pipeline.profile.model_error.weighted_system` under ``model``, if already formed.
    shape : ShapeRule
        The body strategy's shape rule (:func:`sphere_shape`, :func:`held_shape`).

    Returns
    -------
    tuple
        The refitted :class:`~jaxlimb.pipeline.stages.RefineResult`, its whitened Jacobian and residuals, whether the
        steps converged (``None`` for the result when they did not) and its residuals (DN).
    """
    s = math.sqrt(s2)
    d = 1.0 - s / np.sqrt(s2 + t2 * S * S)
    J, r, _, _ = weighted_system(rr, model) if system is None else system
    Jw, rw = _whiten(J, Q, d, s), _whiten(r, Q, d, s)
    x = np.array([float(getattr(rr.fit.params, k)) for k in rr.fit.free])
    for _ in range(max_iter):
        step, lam = np.linalg.lstsq(Jw, rw, rcond=None)[0], 1.0
        while lam > 1e-3:
            cand = _moved(frame, rr, x + lam * step, shape)
            Jc, rc, _, _ = weighted_system(cand, model)
            rwc = _whiten(rc, Q, d, s)
            if rwc @ rwc <= rw @ rw * (1.0 + 1e-12):
                break
            lam *= 0.5
        else:
            return rr, Jw, rw, True, r  # no step lowers the cost: already at its minimum
        done = float(np.sum((Jw @ (lam * step)) ** 2)) < 1e-8  # the step below 1e-4 of its own sigmas
        x, rr, Jw, rw, r = x + lam * step, cand, _whiten(Jc, Q, d, s), rwc, rc
        if done:
            return rr, Jw, rw, True, r
    return None, Jw, rw, False, r


def model_spread(best: RefineResult, others: list[tuple[float, RefineResult]]) -> np.ndarray:
    """The model-averaging term of ``best``'s covariance (Hoeting et al. 1999, Eq. 1-2, about the best model): the
    weighted outer products of the other models' moves of the parameters all of them fit, each weight the other's
    evidence relative to the best's.

    Parameters
    ----------
    best : RefineResult
        The chosen fit.
    others : list of (float, RefineResult)
        Each other model's relative weight (its evidence over the best's, at most 1) and its fit.

    Returns
    -------
    np.ndarray (p, p)
        Over ``best``'s free parameters.
    """
    free = best.fit.free
    T = np.zeros((len(free), len(free)))
    for w, o in others:
        idx = [i for i, k in enumerate(free) if k in o.fit.free]
        dx = np.array([float(getattr(o.fit.params, free[i])) - float(getattr(best.fit.params, free[i])) for i in idx])
        T[np.ix_(idx, idx)] += w / (1.0 + w) * np.outer(dx, dx)
    return T


def restricted(basis: tuple[np.ndarray, np.ndarray], J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The field's basis as a least-squares fit's residuals see it: ``Q, S`` of ``(I - J J^+) Q S``.  The residuals
    lack what the fit absorbed of the field; with the field's own basis that lack reads as more field (restricted
    maximum likelihood, Patterson & Thompson 1971, takes it out).

    Parameters
    ----------
    basis : tuple of np.ndarray
        :func:`field_basis`'s ``Q`` ``(n, m)`` and ``S`` ``(m,)``.
    J : np.ndarray (n, q)
        The fit's Jacobian by its free parameters.

    Returns
    -------
    tuple of np.ndarray
        ``Q, S`` of the projected columns.
    """
    U = basis[0] * basis[1]
    return thin_svd(U - J @ np.linalg.lstsq(J, U, rcond=None)[0])


def physical(rr: RefineResult) -> bool:
    """Whether a fit's lunar-Lambert weight ``L`` is in the band of lunar-Lambert-like limbs
    (:func:`~jaxlimb.pipeline.profile.passes.l_band`, the default profile's own test), its width from the one-albedo
    fit's covariance: a field of large amplitude trades with the albedo's mean and its law, and a refit outside the
    band is the field explaining what is not an albedo (another reflectance law, compression artefacts).

    Parameters
    ----------
    rr : RefineResult
        The fit, with its covariance.

    Returns
    -------
    bool
    """
    lo, hi = l_band(rr.fit)
    return bool(lo <= float(rr.fit.params.L) <= hi)


def _field_bases(rr: RefineResult) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`field_basis` of ``rr``'s pixels at each correlation length of ``ELL_DEG``, under its lunar-Lambert base
    (a widened profile's extra parameters left out)."""
    p = rr.fit.params
    proj = LimbProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()])
    coords = np.asarray(rr.data.coords, float)
    return [field_basis(proj, coords, math.radians(e)) for e in ELL_DEG]


def field_evidence(rr: RefineResult, bases: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """The restricted negative log marginal likelihood of a least-squares profile fit's residuals with the albedo field
    (the best of ``bases``' correlation lengths, the fit's part of the field taken out: :func:`restricted`), plus one
    per free parameter (Akaike 1974): the score that weighs two models of the same pixels under the field.

    Parameters
    ----------
    rr : RefineResult
        The fit (unweighted).
    bases : list of tuple
        :func:`field_basis` of the pixels at each correlation length.

    Returns
    -------
    float
        Lower is better.
    """
    J, r, _, _ = weighted_system(rr, profile_model(rr.fit.params))
    return min(field_likelihood(r, *restricted(b, J))[2] for b in bases) + len(rr.fit.free)


def field_preferred(fits: list[RefineResult]) -> RefineResult:
    """Of profile fits to the same pixels (a fit and its widenings), the one the albedo field weighs best
    (:func:`field_evidence`): an albedo that changes across the limb reads to a one-albedo score test as a smear, and
    with the field beside both a smear is taken only where the field does not explain the pixels as well.

    Parameters
    ----------
    fits : list of RefineResult
        Unweighted fits of lunar-Lambert-like profiles on the same pixels, the simplest first (kept on a tie).

    Returns
    -------
    RefineResult
    """
    if len(fits) == 1:
        return fits[0]
    bases = _field_bases(fits[0])
    scores = [field_evidence(f, bases) for f in fits]
    return fits[int(np.argmin(scores))]


def albedo_field_refit(frame: Frame, rr: RefineResult, base: RefineResult | None = None) -> RefineResult | None:
    """``rr`` (a profile fit, widened or not) refitted with the albedo as a marginalised Gaussian field (module
    docstring); ``None`` when its data are weighted, the refit fails or is not physical (:func:`physical`), or a
    glow or smear explains the pixels better (the caller keeps the one-albedo fit).

    Limb brightening and an albedo that darkens toward the limb can explain the same pixels; with ``base`` (the fit
    ``rr`` was widened from) the one of the two whose residuals have the larger marginal likelihood with the field,
    less one per free parameter (Akaike 1974), is refitted.  A glow (above the limb) or a smear (the PSF) is not what
    an albedo inside the limb does: such a fit is weighed without the field (its plain likelihood), and when it is
    the better, the default path answers.  The covariance is the field's, widened by what the field did not explain
    (the cluster-robust term of the whitened residuals over limb sectors) and by the other model's move weighted by its
    evidence (:func:`model_spread`).

    Parameters
    ----------
    frame : Frame
        The frame (its camera sets the sphere's image shape).
    rr : RefineResult
        The one-albedo fit of a lunar-Lambert profile, unweighted.
    base : RefineResult or None
        The unwidened fit ``rr`` was widened from, if it was.

    Returns
    -------
    RefineResult or None
        The refit; ``noise_covariance`` the one-albedo fit's noise-only covariance.
    """
    if rr.data.weights is not None:
        return None
    coords = np.asarray(rr.data.coords, float)
    bases = _field_bases(rr)

    def evidence(c: RefineResult):
        model = profile_model(c.fit.params)
        r = (system := weighted_system(c, model))[1]
        if type(c.fit.params) not in (LimbProfileParams, MinnaertProfileParams):  # a glow or a smear, without field
            return 0.5 * r.size * (1.0 + math.log(r @ r / r.size)) + len(c.fit.free), c, None, None, None, True, 0.0
        (Q, S), (s2, t2, nll) = min(((b, field_likelihood(r, *restricted(b, system[0]))) for b in bases),
                                    key=lambda f: f[1][2])  # (s, tau, ell): the fit's part of the field taken out
        out, Jw, rw, ok, r_out = gls_refit(frame, c, model, Q, S, s2, t2, system=system)
        if not ok or not physical(out.with_covariance(c.fit.covariance)):  # (the band of the one-albedo fit)
            return math.inf, c, out, Jw, rw, False, s2
        nll = field_likelihood(r_out, Q, S)[2]
        return nll + len(c.fit.free), c, out, Jw, rw, ok, s2

    cands = sorted((evidence(c) for c in {id(rr): rr, id(base): base or rr}.values()), key=lambda e: e[0])
    score, rr, out, Jw, rw, _, s2 = cands[0]
    if not math.isfinite(score) or out is None:
        return None
    q = out.fit.params
    C0 = np.linalg.inv(Jw.T @ Jw)
    C = widen(C0, cluster_robust_covariance(Jw, rw, sector_groups(coords, (float(q.r0), float(q.c0)),
                                                                    MODEL_ERROR_SECTORS)))
    C = C + model_spread(out, [(math.exp(score - e[0]), e[2] or e[1]) for e in cands[1:] if math.isfinite(e[0])])
    if not np.all(np.isfinite(C)):
        return None
    fit = eqx.tree_at(lambda f: (f.covariance, f.sigma2), out.fit, (jnp.asarray(C), jnp.asarray(s2)))
    return replace(out, fit=fit, noise_covariance=np.asarray(rr.covariance_noise))


def with_albedo_field(frame: Frame, answer: RefineResult, shape: ShapeRule = sphere_shape) -> RefineResult:
    """A physical profile's answer (its model-error terms but the albedo's, and its witnesses, in its covariance)
    refitted under the albedo field its residuals along the limb ask for: ``locate``'s answer on a
    lunar-Lambert-like limb.

    The field (amplitude, length and the noise) is :func:`~jaxlimb.pipeline.profile.albedo_prior.residual_field`'s;
    the fit is the generalised least squares under ``Sigma = s^2 I + tau^2 U U^T`` (:func:`gls_refit`), whose
    covariance ``(J^T Sigma^-1 J)^-1`` holds the field (Van Trees 1968, Sec. 2.4), widened by the model-error terms of
    :func:`~jaxlimb.pipeline.profile.model_error.with_model_error` on the whitened system, and by what the answer's
    covariance held beyond its own model-error terms (the witnesses of a reweighting, a widening, a glow).  A uniform
    albedo gives ``tau`` near 0: the least-squares answer.  When the steps do not converge, ``answer`` (whose
    covariance holds the field's consider term instead).

    Parameters
    ----------
    frame : Frame
        The frame (its camera sets the sphere's image shape).
    answer : RefineResult
        A least-squares fit of a physical profile (weighted or not) with its model-error terms.
    shape : ShapeRule
        How the limb's shape follows the centre: the sphere's (default) or held (:func:`held_shape`, the ellipsoid).

    Returns
    -------
    RefineResult
        The refit with the widened covariance; ``noise_covariance`` ``answer``'s.

    Notes
    -----
    Runs under one BLAS thread (:func:`~jaxlimb.numerics.one_blas_thread`): the refit's products over the limb's
    pixels then give the same digits whatever the machine's load, so a run killed and resumed matches one run.
    """
    with one_blas_thread():
        return _refit_under_field(frame, answer, shape)


def _refit_under_field(frame: Frame, answer: RefineResult, shape: ShapeRule) -> RefineResult:
    """:func:`with_albedo_field`'s refit, on whatever BLAS threads the caller allows."""
    C0 = np.asarray(answer.noise_covariance)
    rr = answer.with_covariance(C0)
    model = profile_model(rr.fit.params)
    J, r, padded, w = system = weighted_system(rr, model)
    coords = np.asarray(rr.data.coords, float)
    s = signed_distance(rr.fit.params, coords, padded)
    s2, t2, _, U, GU = residual_field(rr.fit.params, coords, J, r, w, s)
    witnesses = np.asarray(answer.fit.covariance) - np.asarray(with_model_error(rr, model=model, system=system,
                                                                               consider=False).fit.covariance)
    Q, S = thin_svd(U)
    out, Jw, rw, ok, _ = gls_refit(frame, rr, model, Q, S, s2, t2, system=system, shape=shape)
    C = np.linalg.inv(Jw.T @ Jw) if ok else None
    if not ok or not np.all(np.isfinite(C)):  # the least-squares answer, with the field's consider term
        idx = split_witness(rr, J, r, s)[0]
        return answer.with_covariance(with_consider_term(answer.fit.covariance, C0, t2 * (GU @ GU.T), idx))
    out = with_model_error(out.with_covariance(C), model=model, system=(Jw, rw, padded, w), consider=False)
    return out.with_covariance(np.asarray(out.fit.covariance) + witnesses, noise_covariance=C0)


__all__ = ["ShapeRule", "albedo_field_refit", "field_basis", "field_evidence", "field_preferred", "gls_refit",
           "held_shape", "model_spread", "physical", "restricted", "sphere_shape", "with_albedo_field"]
