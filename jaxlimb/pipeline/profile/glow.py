"""A glow above the limb (exponential in height, optionally tilted toward the Sun): the score test at fixed scale
heights, the widened profile fit of a round body, the tilt kept or held, and the plausibility bounds shared with the
ellipsoid's profile."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..._programs import stored_jit
from ...errors import ConvergenceError
from ...models import GlowProfileParams, LIMB_PROFILE, LIMB_PROFILE_GLOW, LimbProfileParams
from ...models.profile_columns import glow_column
from ..stages import Frame, RefineResult
from .model_error import last_step, weighted_system
from .passes import profile_passes
from .widen import widen_aniso


GLOW_H0 = (1.0, 0.3)
"""The scale heights (px) of the glow columns of the score test (:func:`glow_step`): the gate's and the edge's."""


GLOW_Z = 3.0
"""The z-score of the glow's one-step estimate at ``GLOW_H0[0]`` above which the profile is refitted with a glow
(and the estimate at ``GLOW_H0[1]`` must be positive): a one-sided score test, a glow only adds light above the
limb.  A threshold tuned on the project's scene families: the glow frames and the non-Gaussian PSFs, whose wings
look like a glow, pass it; uniform-albedo limbs and maria do not (``docs/validation/constants.md#glow_z``)."""


GLOW_MAX = 1.0
"""The largest glow accepted (units of ``amp``: the radiance just above the limb over the disc's scale)."""


GLOW_H_RANGE = (0.05, 10.0)
"""Scale heights (px) accepted: below, the glow is a step on the limb (the limb's own brightness); above, wider
than the annulus the profile is fitted on."""


def glow_step(rr: RefineResult, system=None) -> list[tuple[float, float]]:
    """One Gauss--Newton step of the glow (:class:`~jaxlimb.models.lunar_lambert.GlowProfileParams`, held at 0 in
    ``rr``) at each scale height of :data:`GLOW_H0`, with the free parameters of ``rr`` refitted beside it, and its
    z-score: the score test of :func:`~jaxlimb.pipeline.profile.widen.brightening_step` (the scale height is not
    identified at zero glow, so the test is made at fixed ones).

    Parameters
    ----------
    rr : RefineResult
        A fit of :data:`~jaxlimb.models.LIMB_PROFILE`.
    system : tuple or None
        ``rr``'s :func:`~jaxlimb.pipeline.profile.model_error.weighted_system` ``(J, r, padded, w)``, if formed.

    Returns
    -------
    list of tuple of float
        ``(step, z)`` per scale height of :data:`GLOW_H0` (the glow in units of ``amp``).
    """
    J, r, padded, w = weighted_system(rr, LIMB_PROFILE) if system is None else system
    cols = np.asarray(glow_columns(rr.fit.params, padded, np.asarray(GLOW_H0, float)))[:, : r.size] * w
    return [last_step(np.concatenate([J, c[:, None]], axis=1), r) for c in cols]


@stored_jit
def glow_columns(p, rc, h):
    """:func:`~jaxlimb.models.profile_columns.glow_column` at each scale height ``h``: the score-test columns of
    :func:`glow_step` (one compiled program, stored: :func:`jaxlimb._programs.stored_jit`).

    Parameters
    ----------
    p : LimbProfileParams
        The fitted profile.
    rc : array (n, 2)
        Pixel coordinates (row, column).
    h : array (k,)
        Scale heights of the glow (px).

    Returns
    -------
    array (k, n)
        The glow column at each scale height.
    """
    return jax.vmap(glow_column, in_axes=(None, None, 0))(p, rc, jnp.log(h))


def widen_glow(frame: Frame, rr: RefineResult, solver, system=None) -> RefineResult:
    """``rr`` refitted with a glow above the limb (:data:`~jaxlimb.models.lunar_lambert.LIMB_PROFILE_GLOW`) when
    :func:`glow_step` at ``GLOW_H0[0]`` is positive at more than :data:`GLOW_Z` sigma and positive at
    ``GLOW_H0[1]``; else, or when the refit leaves ``(0, GLOW_MAX]`` or :data:`GLOW_H_RANGE`, ``rr`` itself.  The
    glow's tilt toward the Sun is fitted and kept only when it is significant (:func:`tilt_significant`).

    Why: a glow (exponential above the limb) moves the lunar-Lambert profile's centre by up to most of a
    pixel.  The edge's step at ``GLOW_H0[1]``: a PSF with wider wings than a Gaussian (Airy) also moves light out of
    the limb, but from its first few tenths of a pixel, where a glow adds light.  Rejected refits keep ``rr``, not
    a typed failure: its covariance carries the misfit as model error (split witness) and the answer stays usable;
    a glow outside the bounds is not the glow it is meant for.

    Parameters
    ----------
    frame : Frame
        The frame (camera, options).
    rr : RefineResult
        A round body's profile fit.
    solver : solver or None
        The solver of the refit (``None``: the options').
    system : tuple or None
        ``rr``'s weighted system, if formed.

    Returns
    -------
    RefineResult
        The glow fit, or ``rr``.
    """
    start = glow_start(rr, system)
    if start is None:
        return rr

    def run(fx):
        return profile_passes(frame, rr.data, start, None, None, fx, solver, LIMB_PROFILE_GLOW)

    try:
        (res, sph), fixed = fit_glow_tilt(run, rr.fixed)
        if not tilt_significant(res):
            (res, sph), fixed = run(fixed + ("glow_tilt",)), fixed + ("glow_tilt",)
    except ConvergenceError:
        return rr
    if not glow_plausible(res.params):
        return rr
    return RefineResult(res, rr.data, 0, fixed, sphere=sph)


def with_edge_glow_spread(out: RefineResult, base: RefineResult, system=None) -> RefineResult:
    """``out`` (the answer of a round profile no widening gate took) with the move a glow thinner than the PSF would
    make added to its covariance: ``C + d d^T``, ``d`` the change of ``base``'s free parameters when the glow column at
    the edge height ``GLOW_H0[1]`` is fitted beside them (one Gauss--Newton step from ``base``); nothing when that
    glow comes out at most 0 (a glow only adds light).  The estimate is not moved.

    Why: light a fraction of a pixel above the edge is a glow, or the wing of a PSF that is not Gaussian (a defocus
    disc), or an albedo darker just inside the limb.  The glow column is as significant on the independent renderer's
    defocus and maria frames as on its glow frames, and it moves the centre the same way on all three, so the fit
    cannot say which one it sees.  Fitting the glow helps where it is a glow and costs where it is not (on defocus
    frames the centre moves off and its sigma grows several times); left out, a glow at ``z`` biases the
    centre by about ``z`` times the sigma it would add, whatever the gate's threshold.  So the unwidened answer is
    kept and the move to the other carried as a model-uncertainty term: a consider term whose size is the data's own
    estimate (Tapley, Schutz & Born 2004, Sec. 6.3).

    Parameters
    ----------
    out : RefineResult
        The answer (``base``, or ``base`` with its patchy sectors down-weighted), with its model-error terms.
    base : RefineResult
        The unwidened fit of :data:`~jaxlimb.models.LIMB_PROFILE`.
    system : tuple or None
        ``base``'s weighted system, if formed.

    Returns
    -------
    RefineResult
        ``out`` with the widened covariance, or ``out`` itself.
    """
    J, r, padded, w = weighted_system(base, LIMB_PROFILE) if system is None else system
    if J.shape[0] < max(50, 2 * J.shape[1] + 2):
        return out
    # (both heights, as the score test: the program compiled for it, not one more of another shape)
    c = np.asarray(glow_columns(base.fit.params, padded, np.asarray(GLOW_H0, float)))[1, : r.size] * w
    with_glow = np.linalg.lstsq(np.concatenate([J, c[:, None]], axis=1), r, rcond=None)[0]
    if not with_glow[-1] > 0.0:
        return out
    d = dict(zip(base.fit.free, with_glow[:-1] - np.linalg.lstsq(J, r, rcond=None)[0]))
    free = list(out.fit.free)
    v = np.array([d.get(n, 0.0) for n in free])
    return out.with_covariance(np.array(out.fit.covariance) + np.outer(v, v))


GLOW_TILT_Z = 2.0
"""The z-score (tilt over its sigma) below which :func:`widen_glow` refits a round body's glow with its tilt held at 0
(:func:`tilt_significant`; the two-sided 95 % test).  A tilt the data do not resolve is a free direction the centre
trades against; held at 0 the glow is uniform along the limb.  A threshold tuned on the project's scene families
(``docs/validation/constants.md#glow_tilt_z``)."""


def tilt_significant(res) -> bool:
    """Whether the widened fit ``res`` keeps its glow's tilt (held, or free at least :data:`GLOW_TILT_Z` of its
    sigma).  The tilt is one more free parameter of the glow's shape along the limb, and a tilt the data do not ask
    for is the fit absorbing something else.  Round bodies only: the Earth's widened fit
    (:mod:`jaxlimb.pipeline.ellipsoid.profile`) keeps :func:`fit_glow_tilt`'s choice.

    Parameters
    ----------
    res : LimbFit
        A fit of :data:`~jaxlimb.models.lunar_lambert.LIMB_PROFILE_GLOW`.

    Returns
    -------
    bool
        ``True`` when the tilt is held or significant.
    """
    if "glow_tilt" not in res.free:
        return True
    i = list(res.free).index("glow_tilt")
    var = float(np.asarray(res.covariance)[i, i])
    return abs(float(res.params.glow_tilt)) >= GLOW_TILT_Z * math.sqrt(max(var, 0.0))


def fit_glow_tilt(run, fixed: tuple[str, ...]):
    """``run(fixed)`` with the glow's tilt free, then, when that fit raised :class:`~jaxlimb.errors.ConvergenceError`,
    did not converge, is not plausible or its tilt is not one to keep (:func:`tilt_kept`), with the tilt held at 0.

    Parameters
    ----------
    run : callable
        ``fixed -> (result, extra)``: a widened glow fit holding the parameters ``fixed``.
    fixed : tuple of str
        The parameters held besides the tilt.

    Returns
    -------
    tuple
        ``((result, extra), fixed)``, ``fixed`` with ``"glow_tilt"`` when it was held; the second fit may raise.
    """
    try:
        out = run(fixed)
        res = out[0]
        if bool(res.converged) and glow_plausible(res.params) and tilt_kept(res.params):
            return out, fixed
    except ConvergenceError:
        pass
    fixed = fixed + ("glow_tilt",)
    return run(fixed), fixed


def glow_start(rr: RefineResult, system=None) -> GlowProfileParams | None:
    """The glow gate of :func:`widen_glow` (sphere and ellipsoid alike): the widened profile's start from ``rr`` when
    :func:`glow_step` at ``GLOW_H0[0]`` is positive at more than :data:`GLOW_Z` sigma and positive at
    ``GLOW_H0[1]``.

    Parameters
    ----------
    rr : RefineResult
        A fit of :data:`~jaxlimb.models.LIMB_PROFILE`.
    system : tuple or None
        ``rr``'s weighted system, if formed.

    Returns
    -------
    GlowProfileParams or None
        ``rr``'s parameters with the one-step glow (at most ``GLOW_MAX / 2``) at scale height ``GLOW_H0[0]``;
        ``None`` when the gate stays shut.
    """
    (step, z), (step_edge, _) = glow_step(rr, system)
    if not (step > 0.0 and z > GLOW_Z and step_edge > 0.0):
        return None
    p = rr.fit.params
    return GlowProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], min(step, 0.5 * GLOW_MAX),
                             math.log(GLOW_H0[0]))


GLOW_TILT_MAX = 2.0
"""The largest glow tilt toward the Sun a widened fit keeps (:func:`tilt_kept`): the glow square to the Sun at least a
third of the glow at the Sun's position angle."""


GLOW_TILT_MIN_H_PX = 0.5
"""The smallest scale height (px) at which a widened fit keeps its glow's tilt (:func:`tilt_kept`)."""


def tilt_kept(q: GlowProfileParams) -> bool:
    """Whether a widened fit keeps its glow's tilt toward the Sun (else :func:`fit_glow_tilt` refits with the tilt
    held at 0): ``0 <= glow_tilt <= GLOW_TILT_MAX`` and a scale height of at least :data:`GLOW_TILT_MIN_H_PX`.

    A shell lit by the Sun is brighter where its tangent points are lit more (module docstring of
    :mod:`jaxlimb.models.lunar_lambert`); a tilt away from the Sun is the fit absorbing something else (an Airy
    PSF's wings), and a glow thinner than half a pixel is a step on the limb whose tilt is the limb's own
    photometry.

    Parameters
    ----------
    q : GlowProfileParams
        The widened fit's parameters.

    Returns
    -------
    bool
        ``True`` when the tilt is kept.
    """
    t = float(q.glow_tilt)
    return 0.0 <= t <= GLOW_TILT_MAX and math.exp(float(q.log_h)) >= GLOW_TILT_MIN_H_PX


def glow_plausible(q: GlowProfileParams) -> bool:
    """A widened fit's glow in ``(0, GLOW_MAX]`` on the whole lit limb (``cpsi`` in ``[0, 1]``: ``glow`` and
    ``glow (1 + glow_tilt)`` both in it) and its scale height in :data:`GLOW_H_RANGE`; NaN fails.

    Parameters
    ----------
    q : GlowProfileParams
        The widened fit's parameters.

    Returns
    -------
    bool
        ``True`` when the glow is plausible.
    """
    lh, lo, hi = float(q.log_h), math.log(GLOW_H_RANGE[0]), math.log(GLOW_H_RANGE[1])
    g, g1 = float(q.glow), float(q.glow) * (1.0 + float(q.glow_tilt))
    return 0.0 < g <= GLOW_MAX and 0.0 <= g1 <= GLOW_MAX and lo <= lh <= hi


def widen_aniso_or_glow(frame: Frame, rr: RefineResult, solver, system=None) -> RefineResult:
    """:func:`~jaxlimb.pipeline.profile.widen.widen_aniso` and :func:`widen_glow` of ``rr``; when both refit, the one
    with the smaller residual RMS.  Each one's score gate opens on the other's scenes: a strong glow on a crescent
    looks anisotropic, and a motion smear raises the glow's step.

    Parameters
    ----------
    frame : Frame
        The frame.
    rr : RefineResult
        A round body's profile fit.
    solver : solver or None
        The solver of the refits.
    system : tuple or None
        ``rr``'s weighted system, if formed.

    Returns
    -------
    RefineResult
        The chosen refit, or ``rr`` when neither gate opens.
    """
    aniso = widen_aniso(frame, rr, solver, system)
    glow = widen_glow(frame, rr, solver, system)
    if aniso is rr or glow is rr:
        return glow if aniso is rr else aniso
    return aniso if float(aniso.fit.rms) < float(glow.fit.rms) else glow


__all__ = ["GLOW_H0", "GLOW_H_RANGE", "GLOW_MAX", "GLOW_TILT_MAX", "GLOW_TILT_MIN_H_PX", "GLOW_TILT_Z", "GLOW_Z", "fit_glow_tilt", "glow_columns", "glow_plausible", "glow_start", "glow_step", "tilt_kept", "tilt_significant", "widen_aniso_or_glow", "widen_glow", "with_edge_glow_spread"]
