"""An albedo-patchy limb (maria crossing it) under the one-albedo profile: the sectors whose residuals are far above
the others' down-weighted (an M-estimator whose unit is the sector, Huber 1981 Sec. 7), by Gauss--Newton steps or
full refits, and the reweighting's move kept as a witness."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import numpy as np

from ...model_error import sector_groups
from ...geometry.sphere_image import sphere_from_ellipse_center
from ...models import LimbModel
from ...models.lunar_lambert import profile_model
from ..sigmoid import columns, pad_coords, predict
from ..stages import FitData, Frame, RefineResult
from .passes import l_band, profile_passes, shape_change_px


PATCHY_SECTORS = 24
"""Sectors of equal pixel counts along the limb (:func:`jaxlimb.model_error.sector_groups`) for
:func:`downweight_patchy_sectors`."""


PATCHY_RATIO = 1.5
"""A sector whose mean squared residual exceeds this multiple of the median sector's is down-weighted.  A mare
crossing the limb makes its sectors misfit many times the median, a uniform-albedo limb keeps them near it; the
threshold sits between the two and was tuned on the project's scene families
(``docs/validation/constants.md#patchy_ratio``)."""


PATCHY_PASSES = 4
"""Reweighted passes (each from the previous answer, the weights from its residuals: iteratively reweighted least
squares, Huber 1981 Sec. 7).  A wide mare pulls the first answer, so the first weights underrate its sectors'
misfit; a few passes let the weights settle (``docs/validation/constants.md#patchy_passes``)."""


PATCHY_POWER = 1.5
"""A down-weighted sector's residual weight is ``ratio^-PATCHY_POWER`` (its weight in the normal equations
``ratio^-3``, :func:`patchy_weights`): the more a sector misfits, the less it counts.  Tuned on the project's maria
frames (``docs/validation/constants.md#patchy_passes``)."""


PATCHY_WITNESS = 0.25
"""The fraction of the reweighting's move (:func:`with_reweighting_witness`) carried as the centre's and radius' sigma:
what the weights leave of a mare's pull scales with what they removed.  Tuned on the project's maria and combined
frames by the centre NEES (``docs/validation/constants.md#patchy_witness``)."""


def with_reweighting_witness(out: RefineResult, unweighted: RefineResult) -> RefineResult:
    """``out`` (a fit whose patchy sectors were down-weighted, :func:`downweight_patchy_sectors`) with
    ``(PATCHY_WITNESS |d|)^2`` added to the variances of ``r0`` and ``c0`` (and ``(PATCHY_WITNESS d_a)^2`` to that of
    ``a``), ``d`` the move from the ``unweighted`` fit (0 when the weighting changed nothing).

    Why: the weights remove the sectors a mare crosses, not the mare's whole pull (its edge's taper in the sectors
    kept, the arc left), and the model-error terms of the weighted fit see only what is left of the residuals.
    The same in every direction: what is left is not along the move (as
    :func:`jaxlimb.pipeline.profile.widen.with_aniso_witness`); the noise-only covariance is kept.

    Parameters
    ----------
    out : RefineResult
        The reweighted fit (with its model-error terms).
    unweighted : RefineResult
        The fit before the reweighting.

    Returns
    -------
    RefineResult
        ``out`` with the widened covariance (unchanged unless ``r0, c0, a`` are all free).
    """
    return out.with_move_witness(unweighted, PATCHY_WITNESS)


def sector_misfit(r: np.ndarray, groups: np.ndarray, n_sectors: int) -> np.ndarray:
    """Each sector's mean squared residual over the median sector's (sectors with no pixel: 0).

    Parameters
    ----------
    r : np.ndarray (n,)
        Residuals of the pixels.
    groups : np.ndarray (n,) of int
        Each pixel's sector (:func:`jaxlimb.model_error.sector_groups`).
    n_sectors : int
        Number of sectors.

    Returns
    -------
    np.ndarray (n_sectors,)
        The ratios.
    """
    counts = np.bincount(groups, minlength=n_sectors)
    ms = np.bincount(groups, weights=r * r, minlength=n_sectors) / np.maximum(counts, 1)
    return ms / max(float(np.median(ms[counts > 0])), 1e-300)


def downweight_patchy_sectors(frame: Frame, rr: RefineResult, solver, system=None) -> RefineResult:
    """``rr`` refitted with the sectors of the limb whose residuals are far above the others' down-weighted
    (weight ``ratio^-PATCHY_POWER`` of :func:`sector_misfit` above :data:`PATCHY_RATIO`; an M-estimator whose unit is
    the sector, Huber 1981 Sec. 7).

    Why: the profile assumes one albedo along the lit limb.  A mare crossing the limb changes the profile's
    *radial* shape within a pixel or two of the edge (5 deg of surface from the limb is 0.4 px in the image),
    which an amplitude along the limb cannot follow, and pulls the centre by a tenth of a pixel.  The sectors it
    crosses misfit far above the noise.

    How: each of the :data:`PATCHY_PASSES` reweighted fits is :data:`PATCHY_GN_STEPS` Gauss--Newton steps of the
    weighted problem from the previous answer (Nocedal & Wright 2006, Eq. 10.23), with the Jacobian the profile's
    one-pass columns give beside the intensity: the reweighting moves the answer by hundredths of a pixel, where
    the problem is linear.  A step that is not finite or raises the weighted residual sum, or an answer whose sphere
    shape has moved by 1e-3 px, falls back to full LM refits.

    Parameters
    ----------
    frame : Frame
        The frame (camera, options).
    rr : RefineResult
        The unweighted profile fit.
    solver : solver or None
        The solver of the fallback refits.
    system : tuple or None
        ``rr``'s :func:`~jaxlimb.pipeline.profile.model_error.weighted_system` under the profile, if formed.

    Returns
    -------
    RefineResult
        The reweighted fit (its weights in ``data.weights``); ``rr`` itself when no sector is down-weighted or its
        ``L`` is outside :func:`~jaxlimb.pipeline.profile.passes.l_band`.
    """
    if not _l_described(rr):  # a limb the profile does not describe: no sector weighting can make it one
        return rr
    model = profile_model(rr.fit.params)
    coords, free = np.asarray(rr.data.coords, float), list(rr.fit.free)
    evaluate = _unweighted_system(model, rr, None if system is None else system[2])
    p = rr.fit.params
    r, J = (system[1] / system[3], system[0] / system[3][:, None]) if system is not None else evaluate(p)
    w = None
    for _ in range(PATCHY_PASSES):
        w_pass = patchy_weights(coords, p, r)
        if w_pass is None:
            break
        w = w_pass
        for _ in range(PATCHY_GN_STEPS):
            stepped = _gauss_newton_step(evaluate, p, free, r, J, w)
            if stepped is None:
                return _downweight_by_refits(frame, rr, solver)
            p, r, J = stepped
    if w is None:
        return rr
    return _reweighted_result(frame, rr, p, r, J, w, evaluate.padded) or _downweight_by_refits(frame, rr, solver)


def _l_described(rr: RefineResult) -> bool:
    """Whether the unweighted fit ``rr`` has its ``L`` within :func:`~jaxlimb.pipeline.profile.passes.l_band` (always, with
    ``L`` held).  The band widens by 3 sigma of ``L``, and down-weighting sectors raises that sigma: a fit the profile
    does not describe must not be let back in by its own reweighting (``docs/validation/constants.md#l-band``)."""
    if "L" not in rr.fit.free:
        return True
    lo, hi = l_band(rr.fit)
    return bool(lo <= float(rr.fit.params.L) <= hi)


def patchy_weights(coords: np.ndarray, p, r: np.ndarray) -> np.ndarray | None:
    """Per-pixel weights of one pass of :func:`downweight_patchy_sectors`: ``ratio^-PATCHY_POWER`` in the sectors about
    ``p``'s centre whose :func:`sector_misfit` ratio exceeds :data:`PATCHY_RATIO`, 1 elsewhere.

    Parameters
    ----------
    coords : np.ndarray (n, 2)
        The pixels ``(row, col)``.
    p : LimbProfileParams
        The current answer (its centre ``r0, c0`` defines the sectors).
    r : np.ndarray (n,)
        The unweighted residuals at ``p``.

    Returns
    -------
    np.ndarray (n,) or None
        The weights; ``None`` when no sector exceeds the ratio.
    """
    groups = sector_groups(coords, (float(p.r0), float(p.c0)), PATCHY_SECTORS)
    ratio = sector_misfit(r, groups, PATCHY_SECTORS)
    if not np.any(ratio > PATCHY_RATIO):
        return None
    return np.where(ratio > PATCHY_RATIO, np.maximum(ratio, 1.0) ** -PATCHY_POWER, 1.0)[groups]


PATCHY_GN_STEPS = 2
"""Gauss--Newton steps per reweighted pass of :func:`downweight_patchy_sectors`: the reweighting moves the answer by
hundredths of a pixel, where the problem is nearly linear and two steps reach the LM refit's answer
(``docs/validation/constants.md#patchy_gn_steps``)."""


def _unweighted_system(model: LimbModel, rr: RefineResult, padded=None):
    """``evaluate(p) -> (r, J)``: the unweighted residuals and Jacobian (free parameters of ``rr.fit``) of the
    pixels of ``rr`` under ``model`` at ``p``, one program per bucket (as :func:`weighted_system`)."""

    coords, z = np.asarray(rr.data.coords, float), np.asarray(rr.data.z, float)
    n, names, free = coords.shape[0], model.param_names, list(rr.fit.free)
    if padded is None:
        padded = jax.device_put(pad_coords(coords))

    def evaluate(p):
        f, cols = columns(model)(p, padded)
        return z - np.asarray(f)[:n], np.stack([np.asarray(cols[names.index(k)])[:n] for k in free], axis=1)

    evaluate.padded = padded
    return evaluate


def _gauss_newton_step(evaluate, p, free, r, J, w):
    """One Gauss--Newton step of the ``w``-weighted problem from ``p`` (residuals ``r``, Jacobian ``J``):
    ``(p', r', J')``, or ``None`` when the step is not finite or raises the weighted residual sum."""
    Jw, rw = J * w[:, None], r * w
    try:
        step = np.linalg.solve(Jw.T @ Jw, Jw.T @ rw)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(step)):
        return None
    q = p.replace(**{k: jax.device_put(np.float64(np.asarray(getattr(p, k), np.float64) + d)) for k, d in zip(free, step)})
    r_new, J_new = evaluate(q)
    if not float(np.sum((r_new * w) ** 2)) <= float(np.sum(rw * rw)) * (1.0 + 1e-9):
        return None
    return q, r_new, J_new


def _reweighted_result(frame: Frame, rr: RefineResult, p, r, J, w, padded) -> RefineResult | None:
    r"""The :class:`~jaxlimb.pipeline.stages.RefineResult` of the weighted answer ``p`` (residuals ``r``, Jacobian
    ``J``, weights ``w``): covariance :math:`\hat\sigma^2 (J_w^\top J_w)^{-1}` as the fit's
    (:func:`jaxlimb.fitting.fit._make_fit`), the sphere at ``p``; ``None`` when that sphere's shape differs
    from the one held by 1e-3 px (the LM refits iterate it, :func:`profile_passes`)."""
    sph = None
    if frame.use_camera:
        cam = frame.cam
        sph = sphere_from_ellipse_center(cam.focal_px, cam.principal_point_rc, (float(p.r0), float(p.c0)), float(p.a))
        if shape_change_px(p, sph) >= 1e-3:
            return None
    Jw, rw = J * w[:, None], r * w
    n, q = rw.size, Jw.shape[1]
    rss = float(rw @ rw)
    s2 = rss / (n - q)
    fit = eqx.tree_at(lambda x: (x.params, x.covariance, x.sigma2, x.rms), rr.fit,
                      (p, jax.device_put(s2 * np.linalg.inv(Jw.T @ Jw)), jax.device_put(s2), jax.device_put(math.sqrt(rss / n))))
    data = FitData(rr.data.coords, rr.data.z, w, rr.data.offset, rr.data.scale)
    return RefineResult(fit, data, 0, rr.fixed, sphere=sph)


def _downweight_by_refits(frame: Frame, rr: RefineResult, solver) -> RefineResult:
    """:func:`downweight_patchy_sectors` with full LM refits (each from the previous answer, with the sphere's
    shape iterated): the fallback of its Gauss--Newton steps."""
    model = profile_model(rr.fit.params)
    coords = np.asarray(rr.data.coords, float)
    z = np.asarray(rr.data.z, float)
    p, data, out = rr.fit.params, rr.data, rr
    for _ in range(PATCHY_PASSES):
        w = patchy_weights(coords, p, z - np.asarray(predict(model, p, coords)))
        if w is None:
            break
        data = FitData(data.coords, data.z, w, data.offset, data.scale)
        res, sph = profile_passes(frame, data, p, None, None, rr.fixed, solver, model)
        p, out = res.params, RefineResult(res, data, 0, rr.fixed, sphere=sph)
    return out


__all__ = ["PATCHY_GN_STEPS", "PATCHY_PASSES", "PATCHY_POWER", "PATCHY_RATIO", "PATCHY_SECTORS", "PATCHY_WITNESS", "downweight_patchy_sectors", "patchy_weights", "sector_misfit", "with_reweighting_witness"]
