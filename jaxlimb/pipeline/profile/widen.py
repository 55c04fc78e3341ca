"""The physical profile widened where the data ask for it (score tests, Rao 1948): a Minnaert-like limb brightening
(``kappa``) and an anisotropic blur (a motion smear, ``s2c, s2s``), with the gates and the witness of the latter
shared with the ellipsoid's profile."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import ConvergenceError
from ...models import (AnisoProfileParams, LIMB_PROFILE, LIMB_PROFILE_ANISO, LIMB_PROFILE_MINNAERT, LimbProfileParams,
                       MinnaertProfileParams)
from ...models.lunar_lambert import brightening_column
from ..sigmoid import columns
from ..stages import Frame, RefineResult
from .model_error import edge_sigma, last_step, signed_distance, trailing_step, weighted_system
from .passes import profile_passes


def aniso_step(rr: RefineResult, system=None) -> tuple[float, float]:
    """One Gauss--Newton step of the blur's anisotropy ``(s2c, s2s)`` (held at 0 in ``rr``) with the free parameters
    of ``rr`` refitted beside it: the score test of :func:`brightening_step` for the two terms together.

    Parameters
    ----------
    rr : RefineResult
        A fit of :data:`~jaxlimb.models.LIMB_PROFILE`.
    system : tuple or None
        ``rr``'s :func:`~jaxlimb.pipeline.profile.model_error.weighted_system` under the profile, if formed.

    Returns
    -------
    tuple of float
        ``(frac, chi2)``: the step's size ``hypot(s2c, s2s)`` over ``sigma_e^2 = sigma^2 + 1/12`` and its chi^2
        (2 degrees of freedom); ``(0, 0)`` with too few pixels.
    """

    J, r, padded, w = weighted_system(rr, LIMB_PROFILE) if system is None else system
    p = rr.fit.params
    q = AnisoProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], 0.0, 0.0)
    _, cols = columns(LIMB_PROFILE_ANISO)(q, padded)
    names = LIMB_PROFILE_ANISO.param_names
    A = np.stack([np.asarray(cols[names.index(k)])[: r.size] for k in ("s2c", "s2s")], axis=1) * w[:, None]
    X = np.concatenate([J, A], axis=1)
    if X.shape[0] < max(50, 2 * X.shape[1]):
        return 0.0, 0.0
    d, cov = trailing_step(X, r, 2)
    chi2 = float(d @ np.linalg.solve(cov, d))
    return float(math.hypot(*d)) / (float(p.sigma) ** 2 + 1.0 / 12.0), chi2


def widen_aniso(frame: Frame, rr: RefineResult, solver, system=None) -> RefineResult:
    """``rr`` refitted with an anisotropic blur (:data:`~jaxlimb.models.lunar_lambert.LIMB_PROFILE_ANISO`: ``s2c,
    s2s`` of the blur variance across the limb, ``cos 2psi`` and ``sin 2psi``), the sphere's shape iterated as in
    :func:`~jaxlimb.pipeline.profile.passes.profile_passes`, when the one-step anisotropy clears the gate
    (:func:`aniso_clears`); ``rr`` itself otherwise, or when the refit fails, its variance is not positive or its
    anisotropy is not significant (:func:`aniso_significant`).  Tried before the glow: a smear passes the glow's
    gate too.

    Why: a motion smear blurs the limb more where it runs across it than along it; one isotropic sigma moves the
    fitted limb in and out along the arc (``cos 2psi``) and the centre with it.

    Parameters
    ----------
    frame : Frame
        The frame (camera, options).
    rr : RefineResult
        A round body's profile fit (:class:`~jaxlimb.models.LimbProfileParams`; others are returned unchanged).
    solver : solver or None
        The solver of the refit (``None``: the options').
    system : tuple or None
        ``rr``'s weighted system, if formed.

    Returns
    -------
    RefineResult
        The anisotropic fit, or ``rr``.
    """

    p = rr.fit.params
    if type(p) is not LimbProfileParams:
        return rr
    frac, chi2 = aniso_step(rr, system)
    if not aniso_clears(frac, chi2):
        return rr
    q = AnisoProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], 0.0, 0.0)
    try:
        res, sph = profile_passes(frame, rr.data, q, None, None, rr.fixed, solver, LIMB_PROFILE_ANISO)
    except ConvergenceError:
        return rr
    if not (bool(res.converged) and aniso_plausible(res.params) and aniso_significant(res)):
        return rr
    return RefineResult(res, rr.data, 0, rr.fixed, sphere=sph)


def with_aniso_blur_witness(out: RefineResult, iso: RefineResult) -> RefineResult:
    """``out`` (an anisotropic-blur refit, :func:`widen_aniso`) with half its move from the isotropic fit ``iso`` added
    to the centre's and radius' variances (:func:`with_aniso_witness`): a line smear is not a Gaussian of another
    variance.

    Parameters
    ----------
    out : RefineResult
        The anisotropic refit (with its model-error terms).
    iso : RefineResult
        The isotropic profile fit.

    Returns
    -------
    RefineResult
        ``out`` with the widened covariance.
    """

    return with_aniso_witness(out, iso)


KAPPA_GATE = 0.04
"""The one-step estimate of the limb-brightening exponent ``kappa`` (:func:`brightening_step`) above which the
profile is refitted with ``kappa`` free.  A threshold tuned on the project's scene families: Minnaert limbs lie
above it, the lunar-Lambert, Hapke, Lommel-Seeliger and maria limbs below (``docs/validation/constants.md#kappa_gate``)."""


KAPPA_DISC_CUT = 1.0
"""The disc side of :func:`brightening_step`: pixels more than this many effective PSF sigmas inside the limb."""


KAPPA_DISC_RATIO = 0.5
"""The disc side's step must be at least this fraction of the step on all pixels.  A Minnaert rim brightens the
disc for pixels inward (``mu^-kappa``, ``mu = sqrt(2 depth / R)``); a glow above the limb or a PSF's wings only
the edge and the sky, and a ``kappa`` fitted to those moves the centre away from the truth.  Tuned on the
project's scene families (``docs/validation/constants.md#kappa_disc_ratio``)."""


KAPPA_MAX = 0.6
"""The largest ``kappa`` accepted (Minnaert ``k >= 0.4``); a refit beyond it keeps the lunar-Lambert fit."""


def brightening_step(rr: RefineResult, system=None) -> tuple[tuple[float, float], tuple[float, float]]:
    """One Gauss--Newton step of the profile's limb-brightening exponent ``kappa`` (held at 0 in ``rr``) with all the
    free parameters of ``rr`` refitted beside it, and its z-score (step / its noise sigma): on all the pixels, and
    on the disc side (signed distance below ``-KAPPA_DISC_CUT`` effective PSF sigmas).

    The score (Lagrange-multiplier) test of Rao (1948) read as an estimate: the residuals and Jacobian of the fit
    already made, no new fit.

    Parameters
    ----------
    rr : RefineResult
        A fit of :data:`~jaxlimb.models.LIMB_PROFILE`.
    system : tuple or None
        ``rr``'s :func:`~jaxlimb.pipeline.profile.model_error.weighted_system` under the profile, if formed.

    Returns
    -------
    tuple
        ``((step, z), (step_disc, z_disc))``: ``kappa``'s one-step estimate and z-score on all pixels and on the
        disc side.
    """
    J, r, padded, w = weighted_system(rr, LIMB_PROFILE) if system is None else system
    col = np.asarray(brightening_column(rr.fit.params, padded))[: r.size] * w
    X = np.concatenate([J, col[:, None]], axis=1)
    s = signed_distance(rr.fit.params, np.asarray(rr.data.coords, float), padded)
    disc = s < -KAPPA_DISC_CUT * edge_sigma(rr.fit.params)
    return last_step(X, r), last_step(X[disc], r[disc])


def widen_brightening(frame: Frame, rr: RefineResult, solver, system=None) -> RefineResult:
    """``rr`` refitted with the limb-brightening exponent ``kappa`` free (the radiance times ``(mu0 mu)^-kappa``:
    Minnaert's law ``mu0^k mu^(k-1)`` at ``L = 0``, Minnaert 1941) when :func:`brightening_step` is above
    :data:`KAPPA_GATE` at more than 3 sigma on all pixels and on the disc side, the latter at least
    :data:`KAPPA_DISC_RATIO` of the former; else, or when the refit leaves ``(0, KAPPA_MAX]``, ``rr`` itself.

    Why: a Minnaert rim (``k < 1``) is brighter than any lunar-Lambert rim, and the profile held to lunar-Lambert
    puts the centre a few tenths of a pixel off on such a limb; ``kappa`` always free costs the lunar-Lambert limbs
    accuracy, hence the gate.

    Parameters
    ----------
    frame : Frame
        The frame (camera, options).
    rr : RefineResult
        A round body's profile fit with ``L`` estimated.
    solver : solver or None
        The solver of the refit.
    system : tuple or None
        ``rr``'s weighted system, if formed.

    Returns
    -------
    RefineResult
        The Minnaert-widened fit, or ``rr``.
    """
    (step, z), (step_disc, z_disc) = brightening_step(rr, system)
    if not (step > KAPPA_GATE and z > 3.0 and step_disc > max(KAPPA_GATE, KAPPA_DISC_RATIO * step) and z_disc > 3.0):
        return rr
    p = rr.fit.params
    start = MinnaertProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], min(step, 0.5 * KAPPA_MAX))
    try:
        res, sph = profile_passes(frame, rr.data, start, None, None, rr.fixed, solver, LIMB_PROFILE_MINNAERT)
    except ConvergenceError:
        return rr
    if not 0.0 < float(res.params.kappa) <= KAPPA_MAX:
        return rr
    return RefineResult(res, rr.data, 0, rr.fixed, sphere=sph)


ANISO_MIN_FRAC = 0.12
"""The smallest anisotropy ``hypot(s2c, s2s) / sigma_e^2`` a profile refit is kept with (:func:`widen_aniso_ellipsoid`).
A motion smear is anisotropic by a large fraction of the blur; an isotropic PSF the Gaussian does not match leaves a
small, sometimes significant, anisotropy whose two free terms only move the centre.  Tuned on the project's Earth
frames (``docs/validation/constants.md#aniso_min``)."""


ANISO_MIN_CHI2 = 13.8
"""And significant: ``s^T C_s^-1 s`` above the chi^2(2) 99.9 % point.  The same two bounds gate the sphere's refit on
its one-step anisotropy (:func:`jaxlimb.pipeline.profile.widen.widen_aniso`), which keeps that refit's CPU off the
frames without a smear (``docs/validation/constants.md#aniso_min``)."""


def aniso_clears(frac: float, chi2: float) -> bool:
    """An anisotropy of size ``frac`` (over ``sigma_e^2``) at ``chi2`` is kept: at least :data:`ANISO_MIN_FRAC` and
    :data:`ANISO_MIN_CHI2`.

    Parameters
    ----------
    frac : float
        ``hypot(s2c, s2s) / sigma_e^2``.
    chi2 : float
        ``s^T C_s^-1 s`` of ``s = (s2c, s2s)``.

    Returns
    -------
    bool
        ``True`` when both bounds are met.
    """
    return bool(frac >= ANISO_MIN_FRAC and chi2 >= ANISO_MIN_CHI2)


def aniso_plausible(q: Any) -> bool:
    """The anisotropic blur variance ``sigma^2 + 1/12 + s2c cos 2psi + s2s sin 2psi`` positive at every ``psi``, with
    a margin (``hypot(s2c, s2s) < 0.9 sigma_e^2``), and the amplitude and semi-major axis positive.

    Parameters
    ----------
    q : AnisoProfileParams
        The refit's parameters.

    Returns
    -------
    bool
        ``True`` when plausible.
    """
    v = float(q.sigma) ** 2 + 1.0 / 12.0
    return bool(math.hypot(float(q.s2c), float(q.s2s)) < 0.9 * v and float(q.amp) > 0 and float(q.a) > 0)


def aniso_significant(res: Any) -> bool:
    """The refit's anisotropy at least :data:`ANISO_MIN_FRAC` of ``sigma_e^2`` and at chi^2 >= :data:`ANISO_MIN_CHI2`
    (the chi^2 from the fit's covariance of ``s2c, s2s``).

    Parameters
    ----------
    res : LimbFit
        A fit of :data:`~jaxlimb.models.lunar_lambert.LIMB_PROFILE_ANISO` with ``s2c, s2s`` free.

    Returns
    -------
    bool
        ``True`` when significant; ``False`` also when their covariance is singular.
    """
    q, free = res.params, list(res.free)
    s = np.array([float(q.s2c), float(q.s2s)])
    idx = [free.index("s2c"), free.index("s2s")]
    try:
        chi2 = float(s @ np.linalg.solve(np.asarray(res.covariance)[np.ix_(idx, idx)], s))
    except np.linalg.LinAlgError:
        return False
    return aniso_clears(math.hypot(*s) / (float(q.sigma) ** 2 + 1.0 / 12.0), chi2)


ANISO_WITNESS = 0.5
"""The fraction of the anisotropic refit's move of ``(r0, c0, a)`` kept as model error (:func:`with_aniso_witness`)."""


def with_aniso_witness(out: RefineResult, iso: RefineResult) -> RefineResult:
    """``(w |d|)^2`` added to the variances of ``r0`` and ``c0`` (and ``(w d_a)^2`` to that of ``a``), ``d`` the
    anisotropic refit's move from the isotropic profile ``iso`` and ``w`` = :data:`ANISO_WITNESS`: a line smear is not
    a Gaussian of another variance, so the correction is itself uncertain, and not only along its own direction.

    Parameters
    ----------
    out : RefineResult
        The anisotropic refit.
    iso : RefineResult
        The isotropic profile fit.

    Returns
    -------
    RefineResult
        ``out`` with the widened covariance (unchanged unless ``r0, c0, a`` are all free).
    """
    return out.with_move_witness(iso, ANISO_WITNESS)


__all__ = ["ANISO_MIN_CHI2", "ANISO_MIN_FRAC", "ANISO_WITNESS", "KAPPA_DISC_CUT", "KAPPA_DISC_RATIO", "KAPPA_GATE", "KAPPA_MAX", "aniso_clears", "aniso_plausible", "aniso_significant", "aniso_step", "brightening_step", "widen_aniso", "widen_brightening", "with_aniso_blur_witness", "with_aniso_witness"]
