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
from ..stages import Frame, RefineResult
from .model_error import columns, edge_sigma, last_step, signed_distance, trailing_step, weighted_system
from .passes import profile_passes


def aniso_step(rr: RefineResult, system=None) -> tuple[float, float]:
    """One Gauss--Newton step of the blur's anisotropy ``(s2c, s2s)`` (held at 0 in ``rr``) with the free parameters
    of ``rr`` refitted beside it: its size over ``sigma_e^2`` and its chi^2 (the score test of :func:`brightening_step`;
    ``system``: ``rr``'s :func:`weighted_system` under the profile, if formed)."""

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
    """``rr`` refitted with an anisotropic blur (:data:`~jaxlimb.models.lunar_lambert.LIMB_PROFILE_ANISO`: ``s2c, s2s``
    of the blur variance across the limb, ``cos 2psi`` and ``sin 2psi``), the sphere's shape iterated as in
    :func:`profile_passes`; ``rr`` itself when the refit fails, its variance is not positive or its anisotropy is not
    significant (the ellipsoid's gate, :func:`jaxlimb.pipeline.profile.widen.aniso_significant`: at least 0.12 of
    ``sigma_e^2`` at chi^2(2) 99.9 %).  Tried before the glow: a smear passes the glow's gate too.

    Why: a motion smear blurs the limb more where it runs across it than along it; one isotropic sigma moves the
    fitted limb in and out along the arc (``cos 2psi``) and the centre with it.  Held-out crescents of
    ``benchmarks/families.py`` (``motion``, 1.5-3.5 px smears, phase 129-133 deg): seed 2028 frame 1 0.107 -> 0.018 px,
    frame 0 (which had opened the glow) 0.064 -> 0.006 px, seed 2027 frame 1 0.061 -> 0.018 px."""

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
    to the centre's and radius' variances (:func:`jaxlimb.pipeline.profile.widen.with_aniso_witness`): a line smear
    is not a Gaussian of another variance.  Held-out ``motion`` 1 of seed 2027: 0.018 px off, NEES 9.5 without it."""

    return with_aniso_witness(out, iso)


KAPPA_GATE = 0.04
"""The one-step estimate of the limb-brightening exponent ``kappa`` (:func:`brightening_step`) above which the
profile is refitted with ``kappa`` free.  Measured (``benchmarks/families.py``, Moon, 6 frames each, the fit with
``kappa`` always free): Minnaert limbs (``kappa = 1 - k`` = 0.05-0.45) gave 0.056-0.39; lunar-Lambert, Hapke,
Lommel-Seeliger with surge, maria and ``combined`` gave -0.15 to 0.021."""


KAPPA_DISC_CUT = 1.0
"""The disc side of :func:`brightening_step`: pixels more than this many effective PSF sigmas inside the limb."""


KAPPA_DISC_RATIO = 0.5
"""The disc side's step must be at least this fraction of the step on all pixels.  A Minnaert rim brightens the
disc for pixels inward (``mu^-kappa``, ``mu = sqrt(2 depth / R)``); a glow above the limb or a PSF's wings only
the edge and the sky.  Measured (``benchmarks/families.py``, Moon, 6 frames each; disc-side / all-pixel step):
Minnaert 0.76-1.06; glow -0.06-0.27 (all-pixel steps up to 0.33: the widened fit moved the centre 0.2 px
*away* from the truth there); Airy -2.0 (one frame with an all-pixel step of 0.17)."""


KAPPA_MAX = 0.6
"""The largest ``kappa`` accepted (Minnaert ``k >= 0.4``); a refit beyond it keeps the lunar-Lambert fit."""


def brightening_step(rr: RefineResult, system=None) -> tuple[tuple[float, float], tuple[float, float]]:
    """One Gauss--Newton step of the profile's limb-brightening exponent ``kappa`` (held at 0 in ``rr``) with
    all the free parameters of ``rr`` refitted beside it, and its z-score (step / its noise sigma): on all the
    pixels, and on the disc side (signed distance below ``-KAPPA_DISC_CUT`` effective PSF sigmas).

    The score (Lagrange-multiplier) test of Rao (1948) read as an estimate: the residuals and Jacobian of the
    fit already made, no new fit (``system``: its :func:`weighted_system`, if already formed)."""
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

    Why: a Minnaert rim (``k < 1``) is brighter than any lunar-Lambert rim; the profile held to lunar-Lambert
    put the centre 0.24-0.41 px off on Minnaert Moons (``benchmarks/families.py``), the widened one 0.006-0.016
    px.  Always free, it cost the lunar-Lambert and Hapke Moons 0.004-0.006 px of median accuracy."""
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
Measured on ``benchmarks/families.py``'s Earth frames (attitude known): ``motion`` 0.18-0.53 (chi^2 of ``s2c, s2s``
660-34 000); the isotropic PSFs ``own``, ``lambert``, ``airy``, ``defocus``, ``jpeg``, ``hapke`` at most 0.077 (chi^2
up to 75: a PSF shape the Gaussian does not match, not a smear).  Kept unconditionally, the two free terms moved
those frames by up to 0.015 px (``lambert`` median 0.009 -> 0.015 px)."""


ANISO_MIN_CHI2 = 13.8
"""And significant: ``s^T C_s^-1 s`` above the chi^2(2) 99.9 % point.  The same two bounds gate the sphere's refit on
its one-step anisotropy (:func:`jaxlimb.pipeline.profile.widen.widen_aniso`; ``benchmarks/families.py``, size over
``sigma_e^2`` and chi^2: held-out Moon ``motion`` crescents 0.32-0.81, 237-8467; seed 2026 ``own`` 0, ``airy`` 0,
``glow`` 0, ``hapke`` 1 at most 0.024, 7.2; seed 2028 ``own`` 0 0.019, 13.5), which keeps that refit's CPU (112 -> 148
ms per frame when always run) off the frames without a smear."""


def aniso_clears(frac: float, chi2: float) -> bool:
    """An anisotropy of size ``frac`` (over ``sigma_e^2``) at ``chi2`` is kept: at least :data:`ANISO_MIN_FRAC` and
    :data:`ANISO_MIN_CHI2`."""
    return bool(frac >= ANISO_MIN_FRAC and chi2 >= ANISO_MIN_CHI2)


def aniso_plausible(q: Any) -> bool:
    """The anisotropic blur variance ``sigma^2 + 1/12 + s2c cos 2psi + s2s sin 2psi`` positive at every ``psi`` (the
    line smears of the independent renderer, 1.5-3.5 px on a 0.5-0.8 px Gaussian, stay within half of it)."""
    v = float(q.sigma) ** 2 + 1.0 / 12.0
    return bool(math.hypot(float(q.s2c), float(q.s2s)) < 0.9 * v and float(q.amp) > 0 and float(q.a) > 0)


def aniso_significant(res: Any) -> bool:
    """The refit's anisotropy at least :data:`ANISO_MIN_FRAC` of ``sigma_e^2`` and at chi^2 >= :data:`ANISO_MIN_CHI2`."""
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
    a Gaussian of another variance (a 1.5-3.5 px box on a 0.5-0.8 px Gaussian), so the correction is itself uncertain,
    and not only along its own direction.  ``benchmarks/families.py`` Earth ``motion`` frames 0-11 (seed 2026; 6-11 not
    tuned on): the refit moved the centre 0.015-0.15 px and left 0.004-0.031 px (residual / move 0.04-0.9); frame 10
    (moved 0.153 px along the row, left 0.021 px along the column, where its covariance is 0.003 px thin) had NEES 42
    with the term along ``d`` only, 48 without it."""
    return out.with_move_witness(iso, ANISO_WITNESS)


__all__ = ["ANISO_MIN_CHI2", "ANISO_MIN_FRAC", "ANISO_WITNESS", "KAPPA_DISC_CUT", "KAPPA_DISC_RATIO", "KAPPA_GATE", "KAPPA_MAX", "aniso_clears", "aniso_plausible", "aniso_significant", "aniso_step", "brightening_step", "widen_aniso", "widen_brightening", "with_aniso_blur_witness", "with_aniso_witness"]
