r"""The fit of the physical limb profile (:data:`jaxlimb.models.LIMB_PROFILE`) on a round limb's pixels:
its start from the circular sigmoid, the clipped (saturated) pixels left out, and the sphere-shape
iteration with a camera (as :func:`~jaxlimb.pipeline.sphere.fits.fit_sphere_annulus`).
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import ConfigError
from ...fitting import NormalLM
from ...imaging.prior import sun_direction_image
from ...models import (AnisoProfileParams, CircleParams, LIMB_PROFILE, LimbProfileParams, lunar_lambert_slope,
                       lunar_lambert_weight, PROFILE_FIXED)
from ..sigmoid import LOGISTIC_TO_GAUSS, predict
from ..stages import FitData, Frame, RefineResult
from .albedo_field import albedo_field_refit
from .glow import widen_aniso_or_glow, with_edge_glow_spread
from .model_error import weighted_system, with_model_error
from .passes import gaussian_sigma_of_k, PROFILE_HELD, profile_passes
from .patchy import downweight_patchy_sectors, with_reweighting_witness
from .widen import widen_brightening, with_aniso_blur_witness


def _inv_focal(frame: Frame, radius_px: float) -> float:
    """``1/f`` (px^-1); without a camera from the range prior (``tan(asin(R/D)) / radius``), else 0 (orthographic)."""
    if frame.cam is not None:
        return 1.0 / frame.cam.focal_px
    h = frame.hints
    rng, rkm = (h.range_prior_km, h.radius_km()) if h is not None else (None, None)
    return (math.tan(math.asin(rkm / rng)) / radius_px) if (rng and rkm and rng > rkm) else 0.0


def profile_sun_direction(sun_dir_camera, camera=None, center_rc=None) -> tuple[float, float]:
    """The Sun's image direction ``(sun_r, sun_c)`` of the profile, however close to full or new the phase.

    :func:`~jaxlimb.imaging.sun_direction_image` returns ``None`` below a projected length of 0.02 (phase
    below 1.15 deg or above 178.85 deg): right for choosing a lit side, wrong for the profile, whose limb
    asymmetry is ``sin(phase) cos(psi')`` times a rim of depth ``~ R sin^2(phase)`` with a tail that falls only
    as ``1/sqrt(depth)`` (the ``2 mu0/(mu0 + mu)`` term, module docstring of :mod:`jaxlimb.models.lunar_lambert`):
    even below 1 deg of phase the blurred limb is measurably asymmetric along the Sun, and a profile held along
    another direction moves the centre by more than its sigma.

    Parameters
    ----------
    sun_dir_camera : array_like (3,)
        Direction from the body toward the Sun (camera frame).
    camera : Camera or None
        The camera (``None``: orthographic, the direction's ``(y, x)``).
    center_rc : tuple of float or None
        The body's image ``(row, col)`` (px), where the direction is projected.

    Returns
    -------
    tuple of float
        Unit ``(sun_r, sun_c)``; ``(1, 0)`` only when the direction is undefined (the Sun on the line of sight).
    """
    sun_rc = sun_direction_image(sun_dir_camera, camera, center_rc, min_norm=0.0)
    return (1.0, 0.0) if sun_rc is None else sun_rc


def profile_start(frame: Frame, circle: CircleParams, data: FitData, center) -> LimbProfileParams:
    """The profile's start: the CSF ``circle`` and its levels (``data``: the CSF's, maybe level-normalised), the PSF
    from its ``k`` (:func:`~jaxlimb.pipeline.profile.passes.gaussian_sigma_of_k`), the Sun from the hints, McEwen's
    ``L(phase)`` and ``1/f`` from the camera (or the range prior).

    Parameters
    ----------
    frame : Frame
        The frame; the hints must hold ``sun_dir_camera``.
    circle : CircleParams
        The circular sigmoid fit (Eq. 16 of Mortari et al. 2016).
    data : FitData
        Its data: with weights (level-normalised) ``offset``/``scale`` give the levels in DN.
    center : tuple of float
        The start centre ``(row, col)`` (px; ideal pixels with a distorted camera).

    Returns
    -------
    LimbProfileParams
        The start (round: ``rho = 1``, ``theta = 0``).
    """
    p = circle
    h = frame.hints
    assert h is not None and h.sun_dir_camera is not None
    phase = frame.phase((float(p.r0), float(p.c0)))
    sun_rc = profile_sun_direction(h.sun_dir_camera, frame.cam, (float(p.r0), float(p.c0)) if frame.cam is not None
                                   else None)
    normalised = data.weights is not None
    scale = float(data.scale) if normalised else float(p.ymax) - float(p.ymin)
    offset = float(data.offset) if normalised else float(p.ymin)
    return LimbProfileParams(r0=center[0], c0=center[1], a=float(p.radius), theta=0.0, rho=1.0,
                             sigma=gaussian_sigma_of_k(float(p.k)), amp=max(scale, 1e-6), ymin=offset, sun_r=sun_rc[0],
                             sun_c=sun_rc[1], phase=phase, inv_f=_inv_focal(frame, float(p.radius)),
                             L=lunar_lambert_weight(phase), L_slope=lunar_lambert_slope(phase),
                             L_ref=lunar_lambert_weight(phase))


def fit_lunar_profile(frame: Frame, circle: CircleParams, data: FitData, sat: float | None = None
                      ) -> tuple[RefineResult, int]:
    """Refit the pixels of the CSF (``circle`` fitted to ``data``) with the physical lunar-Lambert limb profile,
    widened (limb brightening, smear or glow, patchy sectors) when a score test asks for it, with its model-error
    terms but the albedo's (unwidened: also the move of a glow thinner than the PSF,
    :func:`~jaxlimb.pipeline.profile.glow.with_edge_glow_spread`); clipped pixels are left out when the image
    saturates.

    Parameters
    ----------
    frame : Frame
        The frame; the hints must hold ``sun_dir_camera``.
    circle : CircleParams
        The CSF fit.
    data : FitData
        Its pixels (the values are read again from the image).
    sat : float or None
        The image's clip level (:func:`~jaxlimb.pipeline.profile.passes.saturation_level`), if any.

    Returns
    -------
    tuple
        The :class:`~jaxlimb.pipeline.stages.RefineResult` and the number of clipped pixels left out.
    """
    h, opt = frame.hints, frame.opt
    if h is None or h.sun_dir_camera is None:
        raise ConfigError(f"LocateOptions.profile = {opt.profile!r} needs the Sun direction (hints `sun_dir_camera`)")
    p = circle
    coords = data.coords
    z = frame.img[coords[:, 0].astype(np.int64), coords[:, 1].astype(np.int64)].astype(np.float64)
    center = (float(p.r0), float(p.c0))
    if frame.use_camera:
        coords = frame.to_ideal(coords)
        center = tuple(float(v) for v in frame.to_ideal(np.array(center)))
    init = profile_start(frame, circle, data, center)
    data = FitData(coords, z, None, 0.0, 1.0)
    fixed = PROFILE_HELD
    # a tolerance on the parameters' own scale (px, DN): 1e-10 relative costs ~4 more passes for nothing
    solver = NormalLM(rtol=0.0, atol=1e-7, coarse_stride=1) if opt.solver == "lm" else None
    if sat is None or np.count_nonzero(z >= sat) < 20:  # (a few hot pixels are not a clipped limb)
        res, sph = profile_passes(frame, data, init, center, float(p.radius), fixed, solver)
        base, n_clipped = RefineResult(res, data, 0, fixed, sphere=sph), 0
        system = weighted_system(base, LIMB_PROFILE)  # (shared by the score tests and the model-error term)
        out = base
        if "L" not in fixed:  # the law adapts: widen it to Minnaert-like limbs when the data ask for it
            out = widen_brightening(frame, out, solver, system)
        if out is base:  # a motion smear or a glow above the limb, when the data ask for it
            out = widen_aniso_or_glow(frame, out, solver, system)
        if opt.profile == "albedo-field" and (field := albedo_field_refit(frame, out, base)) is not None:
            return field, n_clipped
        if out is base:
            return _unwidened(frame, base, solver, system), n_clipped
    else:
        s_e = LOGISTIC_TO_GAUSS / max(float(p.k), 1e-6)
        out, n_clipped = _fit_clipped(frame, data, init, center, float(p.radius), sat, s_e, solver)
        base = out
    reweighted = downweight_patchy_sectors(frame, out, solver)
    final = with_reweighting_witness(with_model_error(reweighted, consider=False), out)
    return (with_aniso_blur_witness(final, base) if isinstance(out.fit.params, AnisoProfileParams) else final), n_clipped


def _unwidened(frame: Frame, base: RefineResult, solver, system) -> RefineResult:
    """The answer of a round profile no widening gate took: its patchy sectors down-weighted (with the weighting's
    witness), its model-error terms, and the move of a glow thinner than the PSF
    (:func:`~jaxlimb.pipeline.profile.glow.with_edge_glow_spread`)."""
    reweighted = downweight_patchy_sectors(frame, base, solver, system)
    answer = (with_model_error(base, system=system, consider=False) if reweighted is base
              else with_reweighting_witness(with_model_error(reweighted, consider=False), base))
    return with_edge_glow_spread(answer, base, system)


def _fit_clipped(frame: Frame, data: FitData, init: LimbProfileParams, center, radius: float, sat: float,
                 s_e: float, solver) -> tuple[RefineResult, int]:
    """The profile with clipped pixels left out.  A sensor clips at its full well *before* the read noise,
    so clipped pixels scatter a few DN below the top code: fit the pixels 4 noise sigmas below it, then
    keep those whose *model* value is (a selection that does not depend on the noise) and refit.  The
    noise sigma: robust spread of the sky side of the annulus.  The clipped interior hides the brightness
    profile that sets ``L``: it is held (McEwen's or the given value)."""
    coords, z = data.coords, data.z
    d_c = np.hypot(coords[:, 0] - center[0], coords[:, 1] - center[1])
    sky = z[d_c > radius + 3.0 * s_e]
    noise = 1.4826 * float(np.median(np.abs(sky - np.median(sky)))) if sky.size >= 20 else 1.0
    margin = 4.0 * max(noise, 0.5)
    keep = z < sat - margin
    n_clipped = int(np.count_nonzero(~keep))
    fixed = PROFILE_FIXED
    res, sph = profile_passes(frame, data.subset(keep), init, center, radius, fixed, solver)
    pred = predict(LIMB_PROFILE, res.params, coords)
    data = data.subset((pred < sat - margin) & (z < sat))
    res, sph = profile_passes(frame, data, res.params, None, None, fixed, solver)
    return RefineResult(res, data, 0, fixed, sphere=sph), n_clipped


__all__ = ["fit_lunar_profile", "profile_start", "profile_sun_direction"]
