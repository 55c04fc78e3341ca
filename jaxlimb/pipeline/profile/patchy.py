"""An albedo-patchy limb (maria crossing it) under the one-albedo profile: the sectors whose residuals are far above
the others' down-weighted (an M-estimator whose unit is the sector, Huber 1981 Sec. 7), by Gauss--Newton steps or
full refits, and the reweighting's move kept as a witness."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import numpy as np

from ...fitting import bucket_size
from ...model_error import sector_groups
from ...geometry.sphere_image import sphere_from_ellipse_center
from ...models import LimbModel
from ...models.lunar_lambert import profile_model
from ..sigmoid import predict
from ..stages import FitData, Frame, RefineResult
from .model_error import columns
from .passes import l_band, profile_passes, shape_change_px


PATCHY_SECTORS = 24
"""Sectors of equal pixel counts along the limb (:func:`jaxlimb.model_error.sector_groups`) for
:func:`downweight_patchy_sectors`."""


PATCHY_RATIO = 1.5
"""A sector whose mean squared residual exceeds this multiple of the median sector's is down-weighted.
Measured (``benchmarks/families.py``, Moon, 6 frames per family, fit of main 002f51e): 2-60 in the sectors a
mare crosses (4-6 such sectors on 5 of the 6 maria frames), at most 1.6 on uniform-albedo lunar-Lambert,
Minnaert, glow, Airy, defocus, JPEG and star frames; 2.0-3.1 in 1-3 sectors of one Hapke, one
Lommel-Seeliger, two motion-smeared and one JPEG frame, whose answers moved by at most 0.007 px.
2.0 until held-out seed 2028 (n 6): its maria 3 and 4 are subtle (ratios 1.6-3.0 in the sectors the maria cross),
the maria median 0.054 px (frames 0 / 4 0.148 / 0.055); with 1.5 0.036 (0.083 / 0.018; frame 2 0.094 -> 0.119, its
covariance covering it, :func:`with_reweighting_witness`).  On the tuning seeds (with the glow's tilt test and the
witness): seed 2026 combined max 0.093 -> 0.044, jpeg max 0.114 -> 0.101, minnaert 3 0.012 -> 0.027; seed 2027
combined median / max 0.037 / 0.136 -> 0.027 / 0.106, maria 0.019 / 0.034 -> 0.017 / 0.027, own 2 0.029 -> 0.014,
cropped 0 0.107 -> 0.119.  Checked on held-out seed 2029 (n 4): maria / combined median 0.033 / 0.045 -> 0.026 /
0.031, other families unchanged but glow 0 0.023 -> 0.031."""


PATCHY_PASSES = 4
"""Reweighted passes (each from the previous answer, the weights from its residuals).  Two passes with the weight
``ratio^-1/2`` stopped half way on wide maria: held-out frames (``benchmarks/families.py --seed 2027/2028``) combined 0
(three maria over 50 deg of the lit limb about the sub-solar point) 0.249 px, maria 0 of seed 2028 0.309 px; with
:data:`PATCHY_POWER` 1.5 and 4 passes 0.134 / 0.142 px (8 passes: the same to 1e-3 px)."""


PATCHY_POWER = 1.5
"""A down-weighted sector's residual weight is ``ratio^-PATCHY_POWER`` (its weight in the normal equations
``ratio^-3``, :func:`patchy_weights`).  Measured on the held-out maria / combined frames above (4 passes): power 0.5
0.207 / 0.046 / 0.027 px (combined 0, maria 2 and 0 of seed 2027), 1.0 0.146 / 0.028 / 0.020, 1.5 0.134 / 0.027 /
0.010, 2.0 0.132 / -, maria 1 of seed 2028 0.036 -> 0.012 (1.5) / 0.011 (2.0)."""


PATCHY_WITNESS = 0.25
"""The fraction of the reweighting's move (:func:`with_reweighting_witness`) carried as the centre's and radius' sigma.
Chosen on seeds 2026 and 2027 of ``benchmarks/families.py`` (``maria`` and ``combined``, 18 reweighted frames): the
centre error left over the move 0.02-1.8, median 0.22.  Mean centre NEES with 0 / 0.25 / 0.5 (recomputed from the
records' covariances): seed 2026 maria 1.19 / 0.83 / 0.65, combined 2.07 / 1.20 / 1.11, seed 2027 maria 1.68 / 0.83 /
0.50, combined 2.22 / 0.40 / 0.20; held-out seed 2028 (n 6) maria 8.57 / 1.70, combined 1.98 / 0.47, seed 2029 (n 4)
maria 2.27 / 0.83, combined 1.31 / 1.28.  The term was looked for after seed 2028's maria 2 (below)."""


def with_reweighting_witness(out: RefineResult, unweighted: RefineResult) -> RefineResult:
    """``out`` (a fit whose patchy sectors were down-weighted, :func:`downweight_patchy_sectors`) with
    ``(PATCHY_WITNESS |d|)^2`` added to the variances of ``r0`` and ``c0`` (and ``(PATCHY_WITNESS d_a)^2`` to that of
    ``a``), ``d`` the move from the ``unweighted`` fit (0 when the weighting changed nothing).

    Why: the weights remove the sectors a mare crosses, not the mare's whole pull (its edge's taper in the sectors
    kept, the arc left), and the model-error terms of the weighted fit see only what is left of the residuals.
    Held-out ``maria`` 2 of seed 2028 (``benchmarks/families.py``: three maria across the lit limb and two more
    near it; any subset of them 0.003-0.024 px): moved 0.28 px, left 0.094 px across the move for a sigma of
    0.015-0.022 px (NEES 40).  The same in every direction: what is left is not along the move (as
    :func:`jaxlimb.pipeline.profile.widen.with_aniso_witness`); the noise-only covariance is kept."""
    return out.with_move_witness(unweighted, PATCHY_WITNESS)


def sector_misfit(r: np.ndarray, groups: np.ndarray, n_sectors: int) -> np.ndarray:
    """Each sector's mean squared residual over the median sector's (sectors with no pixel: 0)."""
    counts = np.bincount(groups, minlength=n_sectors)
    ms = np.bincount(groups, weights=r * r, minlength=n_sectors) / np.maximum(counts, 1)
    return ms / max(float(np.median(ms[counts > 0])), 1e-300)


def downweight_patchy_sectors(frame: Frame, rr: RefineResult, solver, system=None) -> RefineResult:
    """``rr`` refitted with the sectors of the limb whose residuals are far above the others' down-weighted
    (weight ``ratio^-PATCHY_POWER`` of :func:`sector_misfit` above :data:`PATCHY_RATIO`; an M-estimator whose unit is
    the sector, Huber 1981 Sec. 7); ``rr`` itself when no sector is.

    Why: the profile assumes one albedo along the lit limb.  A mare crossing the limb changes the profile's
    *radial* shape within a pixel or two of the edge (5 deg of surface from the limb is 0.4 px in the image),
    which an amplitude along the limb cannot follow (measured: it did not help), and pulls the centre by up
    to 0.11 px.  The sectors it crosses misfit far above the noise.  Measured on the independent maria frames
    (``benchmarks/families.py``): centre median / max 0.048 / 0.115 -> 0.023 / 0.043 px, ``combined`` (Hapke,
    maria, any PSF, JPEG) 0.078 / 0.100 -> 0.015 / 0.093 px.

    How: each of the :data:`PATCHY_PASSES` reweighted fits is :data:`PATCHY_GN_STEPS` Gauss--Newton steps of the
    weighted problem from the previous answer (Nocedal & Wright 2006, Eq. 10.23), with the Jacobian the profile's
    one-pass columns give beside the intensity: the reweighting moves the answer by hundredths of a pixel, where
    the problem is linear.  Measured on the 12 maria and combined frames: the centres of the full LM refits to
    <= 1e-4 px and their NEES to 0.05, for a third of their CPU.  A step that is not finite or raises the
    weighted residual sum, or an answer whose sphere shape has moved by 1e-3 px, falls back to the LM refits
    (:func:`_downweight_by_refits`).  ``system``: ``rr``'s :func:`weighted_system` under the profile, if formed.
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
    ``L`` held).  The band widens by 3 sigma of ``L``, and down-weighting sectors raises that sigma: on a flat 8-bit
    own render (``tests/pipeline/test_cli_locate.py``'s Moon, 30 000 km, phase 30 deg) the fit with ``L`` 1.51 outside
    its band was rejected and the edge fit answered 0.007 px; down-weighted by ``ratio^-1.5`` it came back with ``L``
    1.26-1.41 inside its widened band and the centre 0.23 px off."""
    if "L" not in rr.fit.free:
        return True
    lo, hi = l_band(rr.fit)
    return bool(lo <= float(rr.fit.params.L) <= hi)


def patchy_weights(coords: np.ndarray, p, r: np.ndarray) -> np.ndarray | None:
    """Per-pixel weights of one pass of :func:`downweight_patchy_sectors`: ``ratio^-PATCHY_POWER`` in the sectors about
    ``p``'s centre whose :func:`sector_misfit` ratio exceeds :data:`PATCHY_RATIO`, 1 elsewhere; ``None`` when none does."""
    groups = sector_groups(coords, (float(p.r0), float(p.c0)), PATCHY_SECTORS)
    ratio = sector_misfit(r, groups, PATCHY_SECTORS)
    if not np.any(ratio > PATCHY_RATIO):
        return None
    return np.where(ratio > PATCHY_RATIO, np.maximum(ratio, 1.0) ** -PATCHY_POWER, 1.0)[groups]


PATCHY_GN_STEPS = 2
"""Gauss--Newton steps per reweighted pass of :func:`downweight_patchy_sectors` (one left the centre up to
5e-4 px from the LM refit's on the maria frames, two within 1e-4 px)."""


def _unweighted_system(model: LimbModel, rr: RefineResult, padded=None):
    """``evaluate(p) -> (r, J)``: the unweighted residuals and Jacobian (free parameters of ``rr.fit``) of the
    pixels of ``rr`` under ``model`` at ``p``, one program per bucket (as :func:`weighted_system`)."""

    coords, z = np.asarray(rr.data.coords, float), np.asarray(rr.data.z, float)
    n, names, free = coords.shape[0], model.param_names, list(rr.fit.free)
    if padded is None:
        padded = jax.device_put(np.concatenate([coords, np.repeat(coords[:1], bucket_size(n) - n, axis=0)]))

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
