r"""The profile-refit stage of the ellipsoid strategy: the edge fit's pixels refitted with the blurred
lunar-Lambert radiance (:data:`jaxlimb.models.LIMB_PROFILE`); see "Physical limb profile" in
:mod:`jaxlimb.pipeline.ellipsoid`.

Known attitude: ``theta, rho`` held at the image of the limb spheroid at the current position,
re-predicted after the fit and the fit repeated (once is typical) while they move the ellipse by more
than :data:`~jaxlimb.pipeline.ellipsoid.model.REFIT_TOL_PX`; free ellipse: ``theta, rho`` estimated.  ``profile="auto"`` keeps the edge fit
(``extras["profile_rejected"]`` says why) when the fit fails, its ``L`` is outside the band of
lunar-Lambert-like limbs and its ``L`` under the albedo field is not physical either
(:func:`~jaxlimb.pipeline.profile.passes.in_band`), or it moves the limb by more than half the band from the edge
fit.  An accepted fit is
refitted once with a glow above the limb when a score test finds one (:func:`widen_glow_ellipsoid`), then, with the
attitude known, under the albedo as an unknown Gaussian field, as the sphere's
(:func:`~jaxlimb.pipeline.profile.albedo_field.with_albedo_field`, the shape held): an albedo that changes across the
limb otherwise moves the edge.  An anisotropic blur (:func:`widen_aniso_ellipsoid`) is kept only where the field
weighs it better than the round profile (:func:`~jaxlimb.pipeline.profile.albedo_field.field_preferred`): to a
one-albedo score test such an albedo is a smear.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import ConfigError, ConvergenceError, GeometryError, LimbInputError
from ...fitting import fit
from ...model_error import with_model_error as widen
from ...fitting.solvers import NormalLM, solver_from_name
from ...geometry.conic import ellipse_change
from ...models.ellipse_ramp import ELLIPSE_RAMP, EllipseRampParams
from ...models.lunar_lambert import (AnisoProfileParams, GlowProfileParams, LIMB_PROFILE, LIMB_PROFILE_ANISO,
                                     LIMB_PROFILE_GLOW, LimbProfileParams, lunar_lambert_weight,
                                     MinnaertProfileParams, profile_model)
from ...models.sigmoid import ELLIPSE
from ..profile.albedo_field import field_preferred, held_shape, with_albedo_field
from ..profile.fit import profile_sun_direction
from ..profile.glow import GLOW_Z, fit_glow_tilt, glow_columns, glow_plausible, glow_start
from ..profile.model_error import last_column_step, weighted_system, with_model_error
from ..profile.passes import gaussian_sigma_of_k, l_rejection, PROFILE_HELD
from ..profile.widen import aniso_plausible, aniso_significant, with_aniso_witness
from ..sigmoid import pad_bucket, predict
from ..stages import EllipsoidEdge, FitData, Frame, RefineResult
from .model import as_ellipse, EllipsoidModel, MAX_REFITS, position, REFIT_TOL_PX
from .trace_fit import coherent_shift_var, trace_model_cov


def profile_wanted(frame: Frame, interior_ramp: bool) -> bool:
    """Whether the profile refit runs.  ``profile="auto"``: the physical profile when the Sun direction is known and
    the edge model is the default one (the paper's flat ESF, ``interior_ramp=False``, is a sigmoid experiment: kept
    as it is, as the sphere keeps the papers' fixed-``k`` CSF); ``"lunar-lambert"``: always (needs the Sun);
    ``"sigmoid"``: never.

    Parameters
    ----------
    frame : Frame
        The frame (``opt.profile``, the Sun direction).
    interior_ramp : bool
        The edge model has the interior ramp (``EllipsoidOptions.interior_ramp``).

    Returns
    -------
    bool
        Fit the lunar-Lambert profile.

    Raises
    ------
    ConfigError
        ``profile="lunar-lambert"`` without the Sun direction.
    """
    prof = frame.opt.profile
    if prof == "sigmoid":
        return False
    if not frame.sun_known:
        if prof == "lunar-lambert":
            raise ConfigError("LocateOptions.profile = 'lunar-lambert' needs the Sun direction (hints `sun_dir_camera`)")
        return False
    return prof == "lunar-lambert" or interior_ramp


def _start(body: EllipsoidModel, frame: Frame, edge: EllipsoidEdge, pts: np.ndarray, z: np.ndarray) -> LimbProfileParams:
    """The profile's start: the edge fit's ellipse (shape predicted with a known attitude), the PSF of its
    kernel, the Sun from the hints, and the levels at their linear least-squares values for this geometry
    (the edge fit's ``ymax`` is no radiance scale when its ramp terms carry the interior)."""
    cam, h, e = frame.cam, frame.hints, edge.final.fit.params
    (r0, c0), (a, b), th = edge.fitted
    phase = frame.phase((r0, c0))
    sun_rc = profile_sun_direction(h.sun_dir_camera, cam, (r0, c0))  # (no threshold: phase ~ 0 keeps its side)
    rho0, th0 = body.predicted_shape(cam, -edge.p) if not body.free and body.R is not None else (b / a, th)
    k = float(e.k)
    sigma0 = (math.sqrt(max(1.0 / max(k, 1e-6) ** 2 - 1.0 / 12.0, 0.09)) if isinstance(e, EllipseRampParams)
              else gaussian_sigma_of_k(k))  # the ramp's kernel is a Gaussian of sigma 1/k; the ESF's a logistic
    q = LimbProfileParams(r0=r0, c0=c0, a=float(a), theta=th0, rho=rho0, sigma=sigma0, amp=1.0, ymin=0.0,
                          sun_r=sun_rc[0], sun_c=sun_rc[1], phase=phase, inv_f=1.0 / cam.focal_px,
                          L=lunar_lambert_weight(phase), L_slope=0.0, L_ref=1.0)  # the Earth's weight is no lunar law
    F0 = predict(LIMB_PROFILE, q, np.asarray(pts, float))  # (compiled per bucket, not per limb)
    (amp0, ymin0), *_ = np.linalg.lstsq(np.column_stack([F0, np.ones_like(F0)]), z, rcond=None)
    if not (math.isfinite(amp0) and amp0 > 0):
        amp0, ymin0 = max(float(np.percentile(z, 95)) - float(e.ymin), 1e-6), float(e.ymin)
    return q.replace(amp=float(amp0), ymin=float(ymin0))


def _one_fit(frame: Frame, data: tuple, q: LimbProfileParams, fixed: tuple, i: int):  # noqa: ANN202
    """One profile fit (the parameters' own tolerance, px and DN, as the sphere's); non-finite or
    non-physical answers are failures."""
    solver = None if frame.opt.solver == "lm" else solver_from_name(frame.opt.solver)
    if solver is None:
        solver = NormalLM(rtol=0.0, atol=1e-7) if i == 0 else NormalLM(rtol=0.0, atol=1e-5, coarse_stride=1)
    coords, zz, w = data
    res = fit(LIMB_PROFILE, coords, zz, q, solver, fixed=fixed, weights=w, throw=False)
    if not bool(res.converged):
        raise ConvergenceError(f"the lunar-Lambert limb profile fit ({res.solver}) did not converge: {res.message}")
    q = res.params
    vals = np.array([float(getattr(q, n)) for n in LIMB_PROFILE.param_names])
    if not np.all(np.isfinite(vals)):
        raise ConvergenceError(f"the lunar-Lambert limb profile fit returned non-finite parameters {vals.tolist()}")
    if float(q.a) <= 0 or float(q.rho) <= 0 or float(q.amp) <= 0:
        raise GeometryError(f"limb profile fit gave a non-physical limb: a = {float(q.a)}, rho = {float(q.rho)}, "
                            f"sigma = {float(q.sigma)}, amp = {float(q.amp)}")
    return res, q.replace(sigma=abs(float(q.sigma)))  # the model depends on sigma^2 only (|sigma| reported)


def _passes(body: EllipsoidModel, frame: Frame, edge: EllipsoidEdge, fd: FitData, band: float):  # noqa: ANN202
    """The profile fits with the shape re-predicted at each new position (module docstring)."""

    fixed = PROFILE_HELD
    if body.free:
        fixed = tuple(n for n in fixed if n not in ("theta", "rho"))
    data = pad_bucket(fd)
    q, p, hist, res = _start(body, frame, edge, fd.coords, fd.z), edge.p, [], None
    for i in range(MAX_REFITS):
        res, q = _one_fit(frame, data, q, fixed, i)
        pf = as_ellipse(q)
        moved = ellipse_change(edge.fitted, pf)
        if not moved <= 0.5 * band:  # a sub-pixel correction of the edge fit is expected
            raise GeometryError(f"the limb profile fit moved the limb by {moved:.3g} px from the edge fit "
                                f"(more than half the band, {0.5 * band:g} px)")
        p, info = position(body, frame.cam, pf, p)
        hist.append({"fit": i + 1, "range_km": float(np.linalg.norm(p)), "range_iterations": info["iterations"],
                     "fit_steps": int(res.n_steps)})
        if body.free:
            break
        rho, th = body.predicted_shape(frame.cam, -p)
        if ellipse_change(pf, (pf[0], (float(q.a), float(q.a) * rho), th)) < REFIT_TOL_PX:
            break
        q = q.replace(theta=th, rho=rho)
    return res, fixed, hist


def edge_with_model_error(edge: EllipsoidEdge, rejected: Any = None) -> RefineResult:
    """The edge fit's :class:`RefineResult` with the model-error terms of
    :func:`~jaxlimb.pipeline.profile.model_error.with_model_error`: the answer when the profile is not fitted or is
    rejected (a limb the profile does not describe, e.g. Hapke's, whose edge-fit bias exceeds its noise-only
    sigma).  A rejected profile fit is a second model of the same limb: the difference of the two limbs'
    ``(r0, c0, a)``, ``d d^T``, is added as model error too.

    Parameters
    ----------
    edge : EllipsoidEdge
        The edge fit.
    rejected : LimbProfileParams or None
        The rejected profile fit's parameters, if any.

    Returns
    -------
    RefineResult
        The edge fit with its covariance widened.
    """
    model = ELLIPSE_RAMP if isinstance(edge.final.fit.params, EllipseRampParams) else ELLIPSE
    out = with_model_error(edge.final, model=model)
    if rejected is None:
        return out
    # a rejected profile fit (its L outside the physical band) is a second model of the same limb: the
    # difference of the two limbs' geometry is model error too (the edge fit keeps no model of the interior)
    free = list(out.fit.free)
    names = [n for n in ("r0", "c0", "a") if n in free]
    idx = [free.index(n) for n in names]
    d = np.array([float(getattr(rejected, n)) - float(getattr(out.fit.params, n)) for n in names])
    C = np.array(out.fit.covariance)
    C[np.ix_(idx, idx)] += np.outer(d, d)
    return out.with_covariance(C)


def _with_trace_error(out: RefineResult, edge: EllipsoidEdge, replace_block: bool = False) -> RefineResult:
    """The albedo-patchy limb's model error (:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.trace_model_cov`) added to the
    covariance of ``(r0, c0, a)``; ``replace_block``: the geometry is the rays' own fit
    (:func:`~jaxlimb.pipeline.ellipsoid.patchy.ray_geometry`), so its ``(r0, c0, a)`` covariance *is* the rays'
    cluster-robust one (residual noise and albedo bias of whole stretches of rays alike), uncorrelated with
    the band fit's other parameters.  Either way the centre's variance is then floored, in every direction, at the
    shift the bias field hides in the fit (:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.coherent_shift_var`): a floor, not a
    sum, because the sandwich and the witnesses already hold the visible part of the same field (added, it turned
    ``benchmarks/families.py``'s Earth ``combined`` 2, 0.086 px off, into ``center_too_uncertain``)."""

    free = list(out.fit.free)
    names = [n for n in ("r0", "c0", "a") if n in free]
    if len(names) < 3:
        return out
    idx = [free.index(n) for n in names]
    C = np.array(out.fit.covariance)
    if replace_block:
        C[idx, :], C[:, idx] = 0.0, 0.0
        C[np.ix_(idx, idx)] = trace_model_cov(edge.pixels.trace, edge.fitted)
    else:
        C[np.ix_(idx, idx)] += trace_model_cov(edge.pixels.trace, edge.fitted)
    out = out.with_covariance(C)
    return floor_center_var(out, coherent_shift_var(edge.pixels.trace, edge.fitted))


def floor_center_var(out: RefineResult, var: float) -> RefineResult:
    """``out`` with the covariance of its ellipse centre ``(r0, c0)`` raised to at least ``var`` (px^2) in every
    direction: ``C + [var I - C]_+`` (:func:`jaxlimb.model_error.with_model_error`; eigenvalues below ``var``
    lifted to it, eigenvectors kept; the other parameters untouched).

    Parameters
    ----------
    out : RefineResult
        The fit.
    var : float
        The floor (px^2); ``<= 0``: none.

    Returns
    -------
    RefineResult
        ``out`` with the floored covariance (``out`` itself when ``r0, c0`` are not free or ``var <= 0``).
    """

    free = list(out.fit.free)
    if var <= 0.0 or not all(n in free for n in ("r0", "c0")):
        return out
    idx = np.ix_(*(2 * ([free.index("r0"), free.index("c0")],)))
    C = np.array(out.fit.covariance)
    C[idx] = widen(C[idx], var * np.eye(2))
    return out.with_covariance(C)


def _with_witness(out: RefineResult, edge: EllipsoidEdge) -> RefineResult:
    """``d d^T`` added to the covariance of ``(r0, c0, a)``, ``d`` the difference between the answer and the other
    estimate of the same patchy limb (``edge.witness``, :func:`~jaxlimb.pipeline.ellipsoid.patchy.patchy_geometry`), and
    the traced step's asymmetry likewise (``edge.asymmetry``, :func:`~jaxlimb.pipeline.ellipsoid.patchy._asymmetry`)."""
    free = list(out.fit.free)
    if not all(n in free for n in ("r0", "c0", "a")):
        return out
    idx = [free.index(n) for n in ("r0", "c0", "a")]
    C = np.array(out.fit.covariance)
    if edge.witness is not None:
        d = np.asarray(edge.witness, float) - np.array([float(getattr(out.fit.params, n)) for n in ("r0", "c0", "a")])
        C[np.ix_(idx, idx)] += np.outer(d, d)
    if edge.asymmetry is not None:  # the traced step's asymmetry (ellipsoid._asymmetry)
        C[np.ix_(idx, idx)] += np.outer(edge.asymmetry, edge.asymmetry)
    return out.with_covariance(C)


def fit_profile_ellipsoid(body: EllipsoidModel, frame: Frame, edge: EllipsoidEdge, extras: dict[str, Any]) -> RefineResult:
    """The profile-refit stage (module docstring): the lunar-Lambert profile's :class:`RefineResult`, widened by a glow
    (:func:`widen_glow_ellipsoid`) or an anisotropic blur (:func:`widen_aniso_ellipsoid`) when they are significant,
    refitted under the albedo field, with its model-error terms and the unresolved glow's consider covariance; else the
    edge fit's with its model-error terms.  On an albedo-patchy limb the edge fit, with the traced rays' cluster-robust
    covariance, the coherent-shift floor and the witnesses' differences as model error.

    Parameters
    ----------
    body : EllipsoidModel
        The body.
    frame : Frame
        The prepared frame.
    edge : EllipsoidEdge
        The edge fit.
    extras : dict
        The report: ``profile_fits`` or ``profile_rejected`` (and why) is added to it.

    Returns
    -------
    RefineResult
        The final fit.

    Raises
    ------
    ConvergenceError, GeometryError, LimbInputError
        A failed profile fit when ``profile="lunar-lambert"`` (with ``"auto"`` the edge fit answers).
    """
    if not profile_wanted(frame, body.eo.interior_ramp):
        return edge_with_model_error(edge)
    if edge.pixels.patchy:  # the profile's one albedo is not this limb's (clouds): the per-ray step stays
        extras["profile_rejected"] = {"model": "lunar-lambert", "reason": "albedo varies along the lit limb"}
        if edge.pixels.ray_fit:  # the geometry is the rays' (ellipsoid.ray_geometry): their covariance
            return _with_witness(_with_trace_error(edge.final, edge, replace_block=True), edge)
        return _with_witness(_with_trace_error(edge_with_model_error(edge), edge), edge)
    band, fd = body.eo.band_px, edge.final.data
    try:
        res, fixed, hist = _passes(body, frame, edge, fd, band)
    except (ConvergenceError, GeometryError, LimbInputError) as e:
        if frame.opt.profile != "auto":
            raise
        extras["profile_rejected"] = {"model": "lunar-lambert", "reason": f"{type(e).__name__}: {e}"}
        return edge_with_model_error(edge)
    try:  # (an albedo the one-albedo fit reads as another law is the field's: in_band asks of both fits)
        out = _under_field(body, frame, RefineResult(res, fd, 0, fixed))
    except (ConvergenceError, GeometryError, LimbInputError) as e:
        if frame.opt.profile != "auto":
            raise
        out, why = None, f"{type(e).__name__}: {e}"
    rejected = l_rejection(res, res if out is None else out.fit) if frame.opt.profile == "auto" else None
    if rejected is not None:  # not lunar-Lambert-like (Hapke's): keep the edge fit, say why
        extras["profile_rejected"] = rejected
        return edge_with_model_error(edge, res.params)
    if out is None:
        extras["profile_rejected"] = {"model": "lunar-lambert", "reason": why}
        return edge_with_model_error(edge)
    extras["profile_fits"] = hist
    return out


def _under_field(body: EllipsoidModel, frame: Frame, base: RefineResult) -> RefineResult:
    """The profile fit ``base`` widened (a glow, an anisotropic blur the field prefers) and refitted under the albedo
    field (module docstring), with its model-error terms and the unresolved glow's consider term.  A free ellipse (the
    attitude unknown: the field's smooth orders along the limb trade with ``rho, theta``) and a band normalised by each
    ray's own brightness (:func:`~jaxlimb.pipeline.ellipsoid.trace_fit.normalised_band`, a cloudy limb's) keep the
    one-albedo fit."""
    rr = widen_glow_ellipsoid(frame, base)
    ra = rr if body.free else widen_aniso_ellipsoid(frame, rr)  # (a free ellipse's rho, theta are 2 psi terms too)
    system = None
    if body.free or base.data.weights is not None:  # (the field's low orders trade with a free rho, theta as well)
        system = weighted_system(ra, profile_model(ra.fit.params))  # (shared by both covariance terms)
        out = with_model_error(ra, system=system)
    else:
        ra = field_preferred([rr, ra]) if ra is not rr else rr
        out = with_albedo_field(frame, with_model_error(ra, consider=False), held_shape)
    return with_unresolved_glow(body, out if ra is rr else with_aniso_witness(out, rr), system)


def with_unresolved_glow(body: EllipsoidModel, rr: RefineResult, system=None) -> RefineResult:
    """``rr`` (a profile fit without a glow, its PSF round or smeared) with the consider covariance of a glow the
    fit did not take (``EllipsoidOptions.unresolved_glow = (g_max, H_lo, H_hi)``: brightness uniform on
    ``[0, g_max]`` in units of ``amp``, scale height uniform on ``[H_lo, H_hi]`` km): ``C + mean_k s_k^2 G_k G_k^T``
    over :data:`UNRESOLVED_GLOW_NODES` scale heights ``H_k`` (midpoints of equal bins), ``G_k = (J^T J)^-1 J^T c_k``
    the fit's response to the unit glow column ``c_k`` (:func:`~jaxlimb.models.profile_columns.glow_column`) at
    ``h_k = H_k a / R_e`` px and ``s_k = min(g_max / sqrt(3), GLOW_Z s_d,k)``: the root mean square of a glow
    uniform up to ``g_max`` or, where the data would see a smaller one, the largest the glow gate can miss
    (:data:`~jaxlimb.pipeline.profile.glow.GLOW_Z` times ``s_d,k``, the data's own sigma of that glow with the fit's
    parameters beside it).  The estimate is not moved.

    Why: a glow of a third of a pixel is an edge shifted outward (its light is the first moment of the step), so
    neither the gate nor the misfit sees it, and the radius it lifts is the range's (the lit arc couples the radius
    to the centre).  The Schmidt consider term of orbit determination (Tapley, Schutz & Born 2004, Sec. 6.3)
    carries that one-sided bias in the covariance without estimating it: a given frame's glow is unknown.

    Parameters
    ----------
    body : EllipsoidModel
        The body (``eo.unresolved_glow``, the limb radius).
    rr : RefineResult
        The profile fit.
    system : tuple or None
        ``rr``'s weighted system ``(J, r, padded, w)`` under its profile
        (:func:`~jaxlimb.pipeline.profile.model_error.weighted_system`), if formed.

    Returns
    -------
    RefineResult
        ``rr`` with the widened covariance; ``rr`` itself when the option is off or the fit has a glow.
    """

    p = rr.fit.params
    if body.eo.unresolved_glow is None or isinstance(p, (GlowProfileParams, MinnaertProfileParams)):
        return rr
    g_max, H_lo, H_hi = body.eo.unresolved_glow
    k = UNRESOLVED_GLOW_NODES
    H = H_lo + (H_hi - H_lo) * (np.arange(k) + 0.5) / k
    h = H * float(p.a) / (body.equatorial_km + body.atmosphere_km)
    if g_max <= 0.0 or not np.all(h > 0.0):
        return rr
    J, r, padded, w = weighted_system(rr, profile_model(p)) if system is None else system
    q = LimbProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()])  # (a smear's column: round)
    cols = np.asarray(glow_columns(q, padded, np.asarray(h, float)))[:, : r.size] * w
    C = np.array(rr.fit.covariance)
    for c in cols:
        G = np.linalg.lstsq(J, c, rcond=None)[0]
        C += _consider_var(J, r, c, g_max) * np.outer(G, G) / k
    return rr.with_covariance(C)


UNRESOLVED_GLOW_NODES = 4
"""Scale heights of :func:`with_unresolved_glow`'s average over the glow's prior (midpoints of equal bins)."""


def _consider_var(J: np.ndarray, r: np.ndarray, c: np.ndarray, g_max: float) -> float:
    """``s_k^2`` of :func:`with_unresolved_glow` for the column ``c``: ``min(g_max / sqrt(3), GLOW_Z s_d)^2``, ``s_d``
    the sigma of the column's coefficient fitted beside ``J`` (:func:`~jaxlimb.pipeline.profile.model_error.last_column_step`)."""

    _, var = last_column_step(np.concatenate([J, c[:, None]], axis=1), r)
    return min(g_max / math.sqrt(3.0), GLOW_Z * math.sqrt(max(var, 0.0))) ** 2


def _widened_fit(frame: Frame, rr: RefineResult, model: Any, start: Any, fixed: tuple[str, ...]) -> Any:
    """``model`` fitted from ``start`` on the pixels of the profile fit ``rr`` (padded bucket, its weights), with the
    chosen solver or ``NormalLM(atol=1e-7)``; not raising (the caller checks convergence)."""
    solver = None if frame.opt.solver == "lm" else solver_from_name(frame.opt.solver)
    solver = NormalLM(rtol=0.0, atol=1e-7) if solver is None else solver
    coords, zz, w = pad_bucket(rr.data)
    return fit(model, coords, zz, start, solver, fixed=fixed, weights=w, throw=False)


def widen_glow_ellipsoid(frame: Frame, rr: RefineResult) -> RefineResult:
    """The ellipsoid's profile ``rr`` refitted with a glow above the limb (:data:`~jaxlimb.models.LIMB_PROFILE_GLOW`,
    the shape ``theta, rho`` held as in ``rr``) when the score test of the sphere's
    :func:`~jaxlimb.pipeline.profile.glow.widen_glow` asks for it (the one-step glow at a 1 px scale height positive
    at z > :data:`~jaxlimb.pipeline.profile.glow.GLOW_Z`, the one at 0.3 px positive); a refit that does not
    converge, or whose glow or scale height leaves the plausible range, keeps ``rr`` (its model-error terms carry
    the misfit).

    Why: an exponential glow above the Earth's limb lifts the lunar-Lambert profile's limb, and the part of that
    lift that varies along the arc moves the centre.  The glow's columns are the Moon's
    (:mod:`jaxlimb.pipeline.profile.glow`); the profile's geometry is the sphere's along each ray, as for
    :data:`~jaxlimb.models.LIMB_PROFILE` on the Earth (module docstring of :mod:`jaxlimb.pipeline.ellipsoid`).

    Parameters
    ----------
    frame : Frame
        The frame (solver choice).
    rr : RefineResult
        The profile fit.

    Returns
    -------
    RefineResult
        The glow fit, or ``rr``.
    """

    q = glow_start(rr)
    if q is None:
        return rr
    (res, _), fixed = fit_glow_tilt(lambda fx: (_widened_fit(frame, rr, LIMB_PROFILE_GLOW, q, fx), None), rr.fixed)
    if not bool(res.converged):
        return rr
    if not (glow_plausible(res.params) and float(res.params.amp) > 0 and float(res.params.a) > 0):
        return rr
    return RefineResult(res, rr.data, 0, fixed)  # the model depends on sigma^2 only (|sigma| reported)


def widen_aniso_ellipsoid(frame: Frame, rr: RefineResult) -> RefineResult:
    """The ellipsoid's lunar-Lambert profile ``rr`` refitted with an anisotropic blur
    (:data:`~jaxlimb.models.LIMB_PROFILE_ANISO`: ``s2c, s2s`` of the variance across the limb, the shape held as in
    ``rr``); a refit that does not converge, whose variance is not positive or whose anisotropy is small
    (:func:`~jaxlimb.pipeline.profile.widen.aniso_significant`) keeps ``rr``.  Not after a glow, and not with a
    free ellipse (its ``rho, theta`` move the limb in a ``2 psi`` pattern too).

    Why: a motion smear blurs the limb more where it runs across it than where it runs along it; one isotropic
    sigma is too wide on part of the lit arc and too narrow on the rest, and with the profile's interior gradient
    that moves the fitted limb in and out along the arc (a ``cos 2psi`` pattern that moves the centre).

    Parameters
    ----------
    frame : Frame
        The frame (solver choice).
    rr : RefineResult
        The profile fit (:class:`~jaxlimb.models.LimbProfileParams`; others are returned unchanged).

    Returns
    -------
    RefineResult
        The anisotropic fit, or ``rr``.
    """

    p = rr.fit.params
    if type(p) is not LimbProfileParams:
        return rr
    q = AnisoProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], 0.0, 0.0)
    res = _widened_fit(frame, rr, LIMB_PROFILE_ANISO, q, rr.fixed)
    if not (bool(res.converged) and aniso_plausible(res.params) and aniso_significant(res)):
        return rr
    return RefineResult(res, rr.data, 0, rr.fixed)


__all__ = ["edge_with_model_error", "fit_profile_ellipsoid", "profile_wanted", "widen_aniso_ellipsoid",
           "widen_glow_ellipsoid", "with_unresolved_glow"]
