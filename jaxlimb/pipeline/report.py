r"""The last stages of :func:`jaxlimb.pipeline.locate`, the same for every body: covariance, Cramér--Rao bound,
physical checks and the :class:`~jaxlimb.pipeline.result.LimbMeasurement`.

Covariance.  The fit's :math:`\hat\sigma^2 (J^\top J)^{-1}` over its free parameters is propagated through the
body-centre map (:class:`~jaxlimb.pipeline.stages.BodyCenter`): the mapped quantities (``center_r``,
``center_c``, ``radius`` or ``range_km`` ...) replace the fit parameters they are a function of, the other
free parameters are carried as they are.  One square matrix, reported as ``{name: {name: value}}``
(docs/design.md).  A model-error term of the map (the free ellipse's unsigned centre offset) is added to the
mapped block.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from .._validate import check_center_sigma
from ..models import (AnisoProfileParams, CIRCLE, CircleParams, CoronaParams, ELLIPSE, ELLIPSE_RAMP, ellipse_coords,
                      EllipseRampParams, LimbDarkenedParams, LimbProfileParams, MinnaertProfileParams)
from ..models.lunar_lambert import glow_fields, profile_model
from ..models.small_disc import SmallDiscParams
from .checks import check_edge_width, check_levels
from .result import LimbMeasurement
from .sigmoid import LOGISTIC_TO_GAUSS, fisher_information
from .stages import BodyCenter, Covariance, Frame, Levels, RefineResult


def covariance(final: RefineResult, geo: BodyCenter) -> Covariance:
    """Stage "covariance": ``J P_fit J^T`` with ``J`` the body-centre map on the mapped parameters and the
    identity on the others (module docstring).

    Parameters
    ----------
    final : RefineResult
        The final fit; ``final.fit.covariance`` is ``P_fit`` over its free parameters.
    geo : BodyCenter
        The body-centre map: outputs, the parameters they depend on, its Jacobian and optional model-error block.

    Returns
    -------
    Covariance
        Rows ``geo.outputs`` then the unmapped free parameters; symmetrised; ``jacobian`` the full ``J``.
    """
    free = list(final.fit.free)
    gidx = [free.index(n) for n in geo.params]
    other = [i for i in range(len(free)) if i not in gidx]
    m = len(geo.outputs)
    J = np.zeros((m + len(other), len(free)))
    J[:m, gidx] = geo.jacobian
    for row, i in enumerate(other):
        J[m + row, i] = 1.0
    P = J @ np.asarray(final.fit.covariance) @ J.T
    if geo.model_cov is not None:
        P[:m, :m] += geo.model_cov
    return Covariance(list(geo.outputs) + [free[i] for i in other], 0.5 * (P + P.T), J)


def crlb(frame: Frame, final: RefineResult, cov: Covariance) -> Covariance | None:
    r"""The Cramér--Rao bound at the estimate with :math:`\hat\sigma` as the noise level, propagated as the
    covariance.  Noise only: the model-error terms of the covariance (the profile's cluster-robust term,
    :func:`~jaxlimb.pipeline.profile.model_error.with_model_error`; the free ellipse's offset) are not in it.  With
    unit pixel weights it is the fit's noise-only covariance :math:`\hat\sigma^2 (J^\top J)^{-1}` (no second
    pass over the pixels); with the level normalisation's weights it is :func:`~jaxlimb.analysis.crlb.crlb`'s
    Fisher information with per-pixel noise ``sigma / w_i``.

    Parameters
    ----------
    frame : Frame
        ``frame.opt.compute_crlb`` switches it on.
    final : RefineResult
        The final fit and its data.
    cov : Covariance
        The reported covariance (its names and Jacobian are reused).

    Returns
    -------
    Covariance or None
        The bound over the covariance's rows, with its correlations (its diagonal's square roots are the result's
        ``crlb``); ``None`` when off or the Fisher matrix is singular.
    """
    if not frame.opt.compute_crlb:
        return None
    C = cov.jacobian @ final.covariance_noise @ cov.jacobian.T
    if final.data.weights is not None:
        fp = final.fit.params
        if isinstance(fp, LimbProfileParams):  # the lunar-Lambert profile or a widened variant
            model = profile_model(fp)
        else:
            model = {CircleParams: CIRCLE, EllipseRampParams: ELLIPSE_RAMP}.get(type(fp), ELLIPSE)
        sigma = math.sqrt(max(float(final.fit.sigma2), 1e-300))
        try:
            C = cov.jacobian @ np.linalg.inv(fisher_information(model, fp, final.data, final.fixed, sigma)) @ cov.jacobian.T
        except np.linalg.LinAlgError:  # pragma: no cover - singular Fisher matrix
            return None
    return Covariance(list(cov.names), 0.5 * (C + C.T), cov.jacobian)


def levels(final: RefineResult) -> Levels:
    """The fitted edge as ``k, ymax, ymin`` (the physical profiles: the logistic ``k`` equivalent to their
    Gaussian edge, ``ymin + amp`` as ``ymax``) and its PSF sigma (``sqrt((1.7/k)^2 - 1/12)`` for a logistic;
    ``1/k`` for the ramp's Gaussian kernel, pixel box included).

    Parameters
    ----------
    final : RefineResult
        The final fit; its data's ``offset``/``scale`` map normalised levels back to DN.

    Returns
    -------
    Levels
        ``k`` (1/px), ``ymax``/``ymin`` (DN), PSF sigma (px; ``inf`` for ``k <= 0``) and, for a physical
        profile, its parameters as a dict.
    """
    fp = final.fit.params
    if isinstance(fp, SmallDiscParams):
        return small_disc_levels(fp)
    if isinstance(fp, (LimbProfileParams, LimbDarkenedParams, CoronaParams)):
        sig = abs(float(fp.sigma))
        s_e = math.sqrt(sig * sig + 1.0 / 12.0)
        if isinstance(fp, LimbProfileParams):
            prof = {"model": "lunar-lambert", "psf_sigma_px": sig, "amp": float(fp.amp),
                    "phase_deg": math.degrees(float(fp.phase)), "L": float(fp.L),
                    "L_slope": float(fp.L_slope), "L_ref": float(fp.L_ref),
                    "kappa": float(fp.kappa) if isinstance(fp, MinnaertProfileParams) else 0.0, **glow_fields(fp),
                    **({"blur_aniso": [float(fp.s2c), float(fp.s2s)]} if isinstance(fp, AnisoProfileParams) else {})}
        elif isinstance(fp, CoronaParams):
            prof = {"model": "corona", "psf_sigma_px": sig, "amp": float(fp.amp), "disc": float(fp.disc),
                    "scale_height_px": math.exp(float(fp.log_h))}
        else:
            prof = {"model": "limb-darkened", "psf_sigma_px": sig, "amp": float(fp.amp), "u1": float(fp.u1),
                    "u2": float(fp.u2)}
        return Levels(LOGISTIC_TO_GAUSS / s_e, float(fp.ymin) + float(fp.amp), float(fp.ymin), sig, prof)
    d = final.data
    k = float(fp.k)
    s_e = (1.0 / abs(k)) if isinstance(fp, EllipseRampParams) else LOGISTIC_TO_GAUSS / abs(k) if k != 0 else math.inf
    sig = math.sqrt(max(s_e * s_e - 1.0 / 12.0, 0.0)) if k > 0 else math.inf
    inside = ramp_inside_level(fp, d) if isinstance(fp, EllipseRampParams) else None
    return Levels(k, float(d.offset + d.scale * float(fp.ymax)), float(d.offset + d.scale * float(fp.ymin)), sig, None,
                  inside)


def ramp_inside_level(fp: EllipseRampParams, data: Any) -> float | None:
    """The interior ramp's brightness inside the limb (DN): the median of the fitted model over the fit's pixels
    more than two blur sigmas (``2 / k``) inside the ellipse.  Its limb level ``ymax`` is not the body's brightness:
    a Lambert limb near zero phase rises from ~0 as ``g_2 sqrt(u)`` (:func:`~jaxlimb.models.ellipse_ramp_intensity`),
    and its ``ymax`` may fit below the sky while the disc is bright.

    Parameters
    ----------
    fp : EllipseRampParams
        The fitted parameters.
    data : FitData
        The fit's pixels and the DN scale.

    Returns
    -------
    float or None
        The level (DN); ``None`` when no pixel lies that deep or ``k <= 0``.
    """
    if not float(fp.k) > 0:
        return None
    x, y = ellipse_coords(fp, data.coords)
    depth = float(fp.rho) * float(fp.a) - np.sqrt(float(fp.rho) ** 2 * np.asarray(x) ** 2 + np.asarray(y) ** 2)
    deep = depth > 2.0 / float(fp.k)
    if not deep.any():
        return None
    z = np.asarray(ELLIPSE_RAMP.intensity(fp, data.coords[deep]))
    return float(data.offset + data.scale * float(np.median(z)))


def small_disc_levels(fp: SmallDiscParams) -> Levels:
    """The few-pixel disc's fit as ``k`` (the logistic equivalent of its Gaussian PSF with the pixel box), ``ymax``
    (``ymin + amp``), ``ymin``, and its numbers (:mod:`jaxlimb.models.small_disc`).

    Parameters
    ----------
    fp : SmallDiscParams
        The fitted few-pixel disc.

    Returns
    -------
    Levels
        ``k`` (1/px), ``ymax`` and ``ymin`` (DN), the PSF sigma (px) and the profile (model, PSF sigma, ``amp``,
        phase in degrees, ``L``, radius in px).
    """
    sig = abs(float(fp.sigma))
    s_e = math.sqrt(sig * sig + 1.0 / 12.0)
    prof = {"model": "small-disc", "psf_sigma_px": sig, "amp": float(fp.amp), "phase_deg": math.degrees(float(fp.phase)),
            "L": float(fp.L), "radius_px": float(fp.a)}
    return Levels(LOGISTIC_TO_GAUSS / s_e, float(fp.ymin) + float(fp.amp), float(fp.ymin), sig, prof)


def check_physical(frame: Frame, lev: Levels, cov: Covariance, what: str) -> None:
    """Stage "checks" (a fit is physical or it is a failure): the body brighter than the sky, the edge blur
    plausible, the centre's sigma within ``max_center_sigma_px``.

    Parameters
    ----------
    frame : Frame
        Its options give ``max_center_sigma_px``.
    lev : Levels
        The fitted edge.
    cov : Covariance
        The reported covariance (its ``center_r``/``center_c`` block, when present).
    what : str
        The fit's name, for the messages.

    Raises
    ------
    NonPhysicalFitError, CenterTooUncertainError
    """
    check_levels(lev.ymax if lev.inside is None else lev.inside, lev.ymin, what)
    if lev.profile is not None and float(lev.profile["amp"]) <= 0:
        check_levels(lev.ymin + float(lev.profile["amp"]), lev.ymin, what)
    check_edge_width(lev.psf_sigma_px, what)
    if "center_r" in cov.names:
        check_center_sigma(cov.block(("center_r", "center_c")), frame.opt.max_center_sigma_px)


def timings(frame: Frame) -> dict[str, float]:
    """Seconds spent in each stage (``frame.timings`` holds the end time of each) and the total.

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    dict of str to float
        Stage name -> duration (s), in the order the stages ran, and ``"total"``.
    """
    out, t = {}, frame.t0
    for name, end in frame.timings.items():
        out[name] = end - t
        t = end
    out["total"] = time.perf_counter() - frame.t0
    return out


def measurement(frame: Frame, cand: Any, final: RefineResult, geo: BodyCenter, cov: Covariance, lev: Levels,
                extras: dict[str, Any], iterations: int) -> LimbMeasurement:
    """Stage "result": the :class:`~jaxlimb.pipeline.result.LimbMeasurement` (the same type for every body).

    Parameters
    ----------
    frame : Frame
    cand : LimbCandidates or PredictedCandidates
        The front end's answer (its ``front_end`` name is reported).
    final : RefineResult
        The final fit.
    geo : BodyCenter
        The body-centre geometry.
    cov : Covariance
    lev : Levels
    extras : dict
        The strategy's intermediate values (``None`` values are dropped).
    iterations : int
        Solver steps of the fits that made the answer.

    Returns
    -------
    LimbMeasurement
        With ``selected_pixels_rc`` (observed pixels) when ``keep_pixels`` is set, the CRLB, and ``extras``
        holding also ``sigma_hat`` (DN) and ``timings_s``.
    """
    pix = None
    if frame.opt.keep_pixels:
        pix = final.coords
        if frame.use_camera and frame.cam is not None and frame.cam.has_distortion:
            pix = frame.cam.distort(final.coords)
    if lev.profile is not None:
        extras = {"profile": lev.profile, **extras}
    extras = {**geo.extras, **extras, "sigma_hat": math.sqrt(max(float(final.fit.sigma2), 0.0)) * final.data.scale,
              "timings_s": timings(frame)}
    bound = crlb(frame, final, cov)
    sigmas = None if bound is None else {n: math.sqrt(max(float(bound.matrix[i, i]), 0.0)) for i, n in enumerate(bound.names)}
    return LimbMeasurement(
        center_rc=(float(geo.center_rc[0]), float(geo.center_rc[1])),
        radius_px=None if geo.radius_px is None else float(geo.radius_px),
        ellipse=geo.ellipse, k=lev.k, ymax=lev.ymax, ymin=lev.ymin, covariance=cov.as_dict(),
        iterations=int(iterations), solver=final.fit.solver, front_end=cand.front_end,
        n_pixels=int(final.fit.n_pixels), los_camera=geo.los, range_km=geo.range_km,
        crlb=sigmas, covariance_noise=None if bound is None else bound.as_dict(),
        extras={k: v for k, v in extras.items() if v is not None},
        selected_pixels_rc=pix)


__all__ = ["check_physical", "covariance", "crlb", "levels", "measurement", "timings"]
