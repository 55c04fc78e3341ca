r"""The predicted-limb sphere strategy of :func:`jaxlimb.pipeline.locate`: a body whose limb the hints predict
(SPICE: camera, range, radii, orientation, expected centre), measured on its whole limb, lit and dark; or a body
larger than the frame, measured on its visible arc.

The stages (:mod:`jaxlimb.pipeline.sphere.whole_limb` has the fits and the method):

* **prepare**: the frame in float64, at least :data:`MIN_MAX_STEPS` solver steps (the shape is held and the
  start is the prediction); for a limb arc the start's centre is found by RANSAC with the radius the range
  predicts (:func:`jaxlimb.imaging.predicted.arc_center`), too-big only when no arc is visible;
* **candidates**: the predicted-limb front end (:mod:`jaxlimb.imaging.predicted`), edges of either polarity;
* **edge fit**: :data:`N_PASSES` whole-limb fits (:func:`~jaxlimb.pipeline.sphere.whole_limb.fit_pass`), the annulus
  narrowed to the fitted edge; Check 4 on the scale against the prediction;
* **profile refit**: a sunlit sphere measured on its lit limb only: the lunar-Lambert profile
  (:func:`jaxlimb.pipeline.profile.fit.fit_lunar_profile`); the covariance the larger of the pixel-independent
  and the cluster-robust one (:func:`~jaxlimb.pipeline.sphere.whole_limb.cluster_covariance`);
* **body-centre mapping**: the sphere's exact map (profile), or the ellipse centre plus the predicted offset with
  the radius and range scaled by ``a / a_pred`` (sigmoid; with both polarities, ``a`` the dark limb's own: the lit
  limb's profile moves the joint scale, :mod:`jaxlimb.pipeline.sphere.polarity_split`); model errors of the edge
  (:data:`EDGE_MODEL_SIGMA_PX` through the arc's gains) and, with both polarities, of their split.

Accuracy: ``tests/mission/test_whole_limb.py`` (renders with exact truth), ``benchmarks/limb_arc.py`` (arcs of a
body larger than the frame) and ``benchmarks/cassini_enceladus.py`` (real frames).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, ClassVar, final

import numpy as np

from ...errors import ConvergenceError, RadiusInconsistentError
from ...geometry.bodies import BODY_TABLE
from ...geometry.hints import Hints
from ...imaging.crop import estimate_noise
from ...imaging.predicted import arc_center, edge_bias_gain, fit_shape, limb_edges, predicted_limb
from ...models import CircleParams, LimbProfileParams
from ...models.lunar_lambert import profile_model
from ..checks import check_edge_width, check_levels
from ..frame import DEFAULT_RADIUS_UNCERTAINTY
from ..profile.albedo_field import with_albedo_field
from ..profile.fit import fit_lunar_profile
from ..result import EllipseResult, LimbMeasurement
from ..sigmoid import LOGISTIC_TO_GAUSS
from ..stages import (Body, BodyCenter, Covariance, FitData, Frame, Levels, PredictedCandidates, PredictedEdge,
                      PredictedPixels, RefineResult)
from .center import ROUND_OUTPUTS, sphere_center
from .edge import EDGE_SIGMAS
from .polarity_split import polarity_split
from .whole_limb import cluster_covariance, fit_pass, select_whole_limb

#: 1-sigma of a limb model's edge position error along the limb (px), per pattern of
#: :func:`~jaxlimb.imaging.predicted.edge_bias_gain`: the physical profile's accuracy on renders of its own
#: family (~0.01-0.02 px).  On short arcs the profile's residual mismatch is larger -- the limb-arc
#: renders' centre errors divided by the arcs' gains are a first-harmonic edge error of -0.018 to -0.058 px
#: (``benchmarks/limb_arc.py``) -- and is covered there by the profile's own split-witness model error
#: (:func:`jaxlimb.pipeline.profile.model_error.split_witness`).  It dominates the centre covariance of short arcs
#: without that term.
EDGE_MODEL_SIGMA_PX = 0.02
#: Solver steps at least: the shape is held and the start is the predicted limb.
MIN_MAX_STEPS = 500
#: Half-length (px) of the edge search along the predicted limb's normals (the pointing uncertainty).
SEARCH_PX = 40.0
#: Half-width (px) of the first annulus about the limb; later ones follow the fitted edge, within [3, 8] px.
FIRST_ANNULUS_PX = 8.0
#: Whole-limb fits, each about the last one's limb.
N_PASSES = 3


def predicted_frame(frame: Frame, arc: bool) -> Frame:
    """Stage "prepare" (module docstring).

    Parameters
    ----------
    frame : Frame
        Needs a camera and hints (range, radius).
    arc : bool
        A body larger than the frame: its start centre is found on the visible arc.

    Returns
    -------
    Frame
        In float64, ``max_steps >= MIN_MAX_STEPS``; for an arc, ``hints.expected_center_rc`` found by RANSAC.
    """
    img = np.asarray(frame.img, dtype=np.float64)
    opt = replace(frame.opt, max_steps=max(frame.opt.max_steps, MIN_MAX_STEPS))
    hints = frame.hints
    assert frame.cam is not None and hints is not None
    if arc:
        rkm = hints.radius_km()
        pr = frame.cam.focal_px * math.tan(math.asin(rkm / hints.range_prior_km))
        u = hints.expected_radius_uncertainty_frac or DEFAULT_RADIUS_UNCERTAINTY
        hints = replace(hints, expected_center_rc=arc_center(img, pr, u, mask=frame.mask))
    return replace(frame, img=img, opt=opt, hints=hints)


def predicted_candidates(frame: Frame) -> PredictedCandidates:
    """Stage "candidates": the predicted limb, its edges and the predicted shape fitted to them.

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    PredictedCandidates
    """
    assert frame.cam is not None and frame.hints is not None
    pred = predicted_limb(frame.cam, frame.hints)
    pts, step, _ = limb_edges(frame.img, pred, mask=frame.mask, search_px=SEARCH_PX)
    coarse, used = fit_shape(pts, pred)
    frame.mark("front_end")
    return PredictedCandidates(pred, pts, step, used, coarse, max(estimate_noise(frame.img), 1e-9))


def whole_limb_edge(frame: Frame, cand: PredictedCandidates, pix: PredictedPixels) -> PredictedEdge:
    """Stage "edge fit": :data:`N_PASSES` whole-limb fits, then Check 4 (the scale within 3 ``u`` of the prediction,
    ``u`` the hints' ``expected_radius_uncertainty_frac``).

    Parameters
    ----------
    frame : Frame
    cand : PredictedCandidates
    pix : PredictedPixels
        The first annulus.

    Returns
    -------
    PredictedEdge
        The last pass's fit, the fitted limb, the last half-width, the arc's edge-bias gains.

    Raises
    ------
    RadiusInconsistentError
        Check 4.
    """
    shape, dr, res, counts = pix.shape, pix.dr, None, None
    for _ in range(N_PASSES):
        res, shape, counts = fit_pass(frame.img, frame.mask, shape, dr, cand.noise, frame.opt)
        dr = float(np.clip(EDGE_SIGMAS * LOGISTIC_TO_GAUSS / max(float(res.fit.params.k), 1e-6), 3.0, 8.0))
    assert res is not None and counts is not None and frame.hints is not None
    u = frame.hints.expected_radius_uncertainty_frac or DEFAULT_RADIUS_UNCERTAINTY
    pred = cand.predicted
    if abs(shape.a / pred.a - 1.0) > 3 * u:
        raise RadiusInconsistentError(
            f"Check 4: the limb's semi-major axis {shape.a:.2f} px differs from the predicted {pred.a:.2f} px by more "
            f"than 3 x {u:g} (expected_radius_uncertainty_frac)")
    frame.mark("refine")
    return PredictedEdge(res, shape, dr, counts, edge_bias_gain(cand.points_rc[cand.used], shape), pred, cand.noise)


def predicted_report(frame: Frame, cand: PredictedCandidates, edge: PredictedEdge) -> dict[str, Any]:
    """The intermediate values of the predicted limb's first stages, for ``extras``.

    Parameters
    ----------
    frame : Frame
    cand : PredictedCandidates
    edge : PredictedEdge

    Returns
    -------
    dict
    """
    pred, coarse, used, step = cand.predicted, cand.shape, cand.used, cand.step
    return {"edge_bias_gain": np.asarray(edge.gain).tolist(), "edge_model_sigma_px": EDGE_MODEL_SIGMA_PX,
            "predicted_limb": {"center_rc": list(pred.center_rc), "semi_axes_px": [pred.a, pred.a * pred.rho],
                               "angle_rad": pred.theta},
            "edge_fit": {"center_rc": list(coarse.center_rc), "a": coarse.a, "n_points": int(used.sum()),
                         "n_lit": int(np.count_nonzero(used & (step > 0))),
                         "n_dark": int(np.count_nonzero(used & (step < 0)))},
            "annulus_px": edge.dr, "angular_bins": edge.counts, "n_outliers": int(edge.fit.n_outliers),
            "scale_vs_predicted": edge.shape.a / pred.a,
            "n_masked": 0 if frame.mask is None else int(frame.mask.size - np.count_nonzero(frame.mask))}


def sunlit_sphere(hints: Hints, counts: dict[str, int]) -> bool:
    """A sphere (equal radii) with the Sun direction known, measured on its lit limb only.

    Parameters
    ----------
    hints : Hints
        Radii (or the body table's), Sun direction.
    counts : dict of str to int
        The angular bins' counts (``bins_dark``: dark-limb bins).

    Returns
    -------
    bool
    """
    radii = hints.body_radii_km
    if radii is None and hints.body in BODY_TABLE:
        radii = BODY_TABLE[hints.body].radii_km
    return (hints.sun_dir_camera is not None and radii is not None and max(radii) - min(radii) < 1e-6 * max(radii)
            and counts["bins_dark"] == 0)


def lit_limb_profile(frame: Frame, edge: PredictedEdge) -> RefineResult:
    """The lunar-Lambert limb profile on the lit limb's annulus, started from the whole-limb fit's circle (the
    pipeline's own refit, :func:`~jaxlimb.pipeline.profile.fit.fit_lunar_profile`): removes the flat-topped
    sigmoid's edge bias (0.35-0.5 px on short arcs).

    Parameters
    ----------
    frame : Frame
    edge : PredictedEdge

    Returns
    -------
    RefineResult
        The profile fit (DN, unit weights).
    """
    data, _ = select_whole_limb(frame.img, frame.mask, edge.shape, FIRST_ANNULUS_PX, edge.noise)
    res, shape = edge.fit, edge.shape
    p = res.fit.params

    def to_dn(y: Any) -> float:
        return float(res.data.offset + res.data.scale * float(y))

    circle = CircleParams(r0=p.r0, c0=p.c0, radius=float(np.sqrt(shape.a * shape.a * shape.rho)), k=p.k,
                          ymax=to_dn(p.ymax), ymin=to_dn(p.ymin))
    z = frame.img[data.coords[:, 0].astype(np.int64), data.coords[:, 1].astype(np.int64)]
    fitted, _ = fit_lunar_profile(frame, circle, FitData(data.coords, z, None, 0.0, 1.0), None)
    return with_albedo_field(frame, fitted)


def larger_covariance(rr: RefineResult, cov_cluster: np.ndarray, extras: dict[str, Any]) -> RefineResult:
    """``rr`` with the cluster-robust covariance when its centre block is the larger (trace), the fit's own kept as the
    noise-only one; both centre sigmas in ``extras``.

    Parameters
    ----------
    rr : RefineResult
    cov_cluster : np.ndarray (p, p)
        Cluster-robust covariance of ``rr``'s free parameters.
    extras : dict
        Updated with both centre sigmas (px).

    Returns
    -------
    RefineResult
    """
    cov_fit = np.asarray(rr.fit.covariance)
    extras["sigma_center_pixel_independent_px"] = [float(math.sqrt(cov_fit[i, i])) for i in (0, 1)]
    extras["sigma_center_cluster_robust_px"] = [float(math.sqrt(cov_cluster[i, i])) for i in (0, 1)]
    if np.trace(cov_cluster[:2, :2]) > np.trace(cov_fit[:2, :2]):
        return rr.with_covariance(cov_cluster, noise_covariance=rr.covariance_noise)
    return rr


def predicted_refit(frame: Frame, edge: PredictedEdge, extras: dict[str, Any]) -> RefineResult:
    """Stage "profile refit" (module docstring): the lit limb's profile of a sunlit sphere, else the whole-limb fit;
    the covariance the larger of the pixel-independent and the cluster-robust one.

    Parameters
    ----------
    frame : Frame
    edge : PredictedEdge
    extras : dict
        Updated with the covariance model or the profile's rejection.

    Returns
    -------
    RefineResult
    """
    assert frame.hints is not None
    if sunlit_sphere(frame.hints, edge.counts):
        try:
            prof = lit_limb_profile(frame, edge)
            cov = cluster_covariance(prof, edge.shape, model=profile_model(prof.fit.params))
            return larger_covariance(prof, cov, extras)
        except ConvergenceError as e:  # the sigmoid's answer stands; say why
            extras["profile_rejected"] = {"model": "lunar-lambert", "reason": str(e)}
    extras["covariance_model"] = "max(pixel-independent, cluster-robust over 10-deg stretches of limb)"
    return larger_covariance(edge.fit, cluster_covariance(edge.fit, edge.shape), extras)


def predicted_center(frame: Frame, edge: PredictedEdge, final: RefineResult) -> BodyCenter:
    """Stage "body-centre mapping" (module docstring), with the edge's model error and, for the sigmoid, the split of
    the two polarities (``extras["polarity_split"]``) in ``model_cov``.

    Parameters
    ----------
    frame : Frame
    edge : PredictedEdge
    final : RefineResult
        The profile (exact sphere map) or the whole-limb ESF (scaled prediction).

    Returns
    -------
    BodyCenter
    """
    model_cov = np.zeros((3, 3))
    model_cov[:2, :2] = EDGE_MODEL_SIGMA_PX**2 * np.asarray(edge.gain).T @ np.asarray(edge.gain)
    p = final.fit.params
    if isinstance(p, LimbProfileParams):
        geo = sphere_center(frame, np.array([float(p.r0), float(p.c0), float(p.a)]), ("r0", "c0", "a"))
        return replace(geo, model_cov=model_cov)
    split = polarity_split(frame.img, frame.mask, edge.fit, edge.shape, edge.dr, edge.noise, frame.opt,
                           tuple(edge.fit.fixed))
    if split is not None:
        model_cov[:2, :2] += np.asarray(split["model_error_cov_px2"])
    return _scaled_center(frame, edge, final, model_cov, {"polarity_split": split})


def _scaled_center(frame: Frame, edge: PredictedEdge, final: RefineResult, model_cov: np.ndarray,
                   extras: dict[str, Any]) -> BodyCenter:
    """The whole-limb sigmoid's map: the ellipse centre plus the predicted body-centre offset; the on-axis radius and
    the range scaled by ``a / a_pred``, ``a`` the dark limb's when the split measured it (its pixel-noise variance
    added to the joint ``a``'s in ``model_cov``)."""
    cam, hints, shape, pred = frame.cam, frame.hints, edge.shape, edge.predicted
    assert cam is not None and hints is not None and hints.range_prior_km is not None
    p = final.fit.params
    split = extras.get("polarity_split") or {}
    a = float(split.get("dark_a_px", shape.a))
    scale = a / pred.a
    rkm = hints.radius_km()
    r_eq = cam.focal_px * math.tan(math.asin(rkm / hints.range_prior_km)) * scale if rkm else pred.a * pred.rho * scale
    center = (float(p.r0) + shape.body_offset_rc[0], float(p.c0) + shape.body_offset_rc[1])
    ell = EllipseResult(center_rc=(float(p.r0), float(p.c0)), semi_axes_px=(shape.a, shape.a * shape.rho),
                        angle_rad=float(shape.theta % math.pi))
    if "dark_a_px" in split:
        model_cov = model_cov.copy()
        model_cov[2, 2] += (r_eq / a * split["dark_sigma_a_px"]) ** 2
    return BodyCenter(center, float(r_eq), ell, tuple(float(v) for v in cam.los(np.array(center))),
                      float(hints.range_prior_km / scale), ROUND_OUTPUTS, ("r0", "c0", "a"),
                      np.diag([1.0, 1.0, r_eq / a]), model_cov, extras)


@final
@dataclass(frozen=True)
class PredictedLimbSphere(Body[PredictedPixels, PredictedEdge]):
    """A body whose limb the hints predict, measured on its whole limb (module docstring); ``arc``: larger than the
    frame, measured on its visible arc."""

    arc: bool = False
    name: ClassVar[str] = "whole-limb"

    def prepare(self, frame: Frame) -> Frame:
        """Stage "prepare": :func:`predicted_frame`.

        Parameters
        ----------
        frame : Frame

        Returns
        -------
        Frame
        """
        return predicted_frame(frame, self.arc)

    def candidates(self, frame: Frame) -> PredictedCandidates:
        """Stage "candidates": :func:`predicted_candidates`.

        Parameters
        ----------
        frame : Frame

        Returns
        -------
        PredictedCandidates
        """
        return predicted_candidates(frame)

    def limb_pixels(self, frame: Frame, cand: PredictedCandidates) -> PredictedPixels:
        """The first annulus: :data:`FIRST_ANNULUS_PX` about the fitted predicted shape.

        Parameters
        ----------
        frame : Frame
        cand : PredictedCandidates

        Returns
        -------
        PredictedPixels
        """
        return PredictedPixels(cand.shape, FIRST_ANNULUS_PX)

    def edge_fit(self, frame: Frame, cand: PredictedCandidates, pixels: PredictedPixels) -> PredictedEdge:
        """Stage "edge fit": :func:`whole_limb_edge`.

        Parameters
        ----------
        frame : Frame
        cand : PredictedCandidates
        pixels : PredictedPixels

        Returns
        -------
        PredictedEdge
        """
        return whole_limb_edge(frame, cand, pixels)

    def report(self, frame: Frame, cand: PredictedCandidates, edge: PredictedEdge) -> dict[str, Any]:
        """The first stages' numbers: :func:`predicted_report`.

        Parameters
        ----------
        frame : Frame
        cand : PredictedCandidates
        edge : PredictedEdge

        Returns
        -------
        dict
        """
        return predicted_report(frame, cand, edge)

    def refit(self, frame: Frame, cand: PredictedCandidates, edge: PredictedEdge, extras: dict[str, Any]) -> RefineResult:
        """Stage "profile refit": :func:`predicted_refit`.

        Parameters
        ----------
        frame : Frame
        cand : PredictedCandidates
        edge : PredictedEdge
        extras : dict

        Returns
        -------
        RefineResult
        """
        return predicted_refit(frame, edge, extras)

    def body_center(self, frame: Frame, edge: PredictedEdge, final: RefineResult) -> BodyCenter:
        """Stage "body-centre mapping": :func:`predicted_center`.

        Parameters
        ----------
        frame : Frame
        edge : PredictedEdge
        final : RefineResult

        Returns
        -------
        BodyCenter
        """
        return predicted_center(frame, edge, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        """The fit is physical (levels, edge blur); no tolerance on the centre's sigma: the covariance carries the
        edge's and the polarities' model errors, which make it honest rather than small.

        Parameters
        ----------
        frame : Frame
        levels : Levels
        cov : Covariance
        """
        check_levels(levels.ymax, levels.ymin, self.name)
        check_edge_width(levels.psf_sigma_px, self.name)

    def iterations(self, edge: PredictedEdge, final: RefineResult) -> int:
        """The final fit's solver steps.

        Parameters
        ----------
        edge : PredictedEdge
        final : RefineResult

        Returns
        -------
        int
        """
        return int(final.fit.n_steps)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """For an arc, the start centre in ``extras["arc_start_center_rc"]``.

        Parameters
        ----------
        frame : Frame
        meas : LimbMeasurement

        Returns
        -------
        LimbMeasurement
        """
        if not self.arc:
            return meas
        assert frame.hints is not None and frame.hints.expected_center_rc is not None
        return replace(meas, extras={**meas.extras, "arc_start_center_rc": list(frame.hints.expected_center_rc)})


__all__ = ["EDGE_MODEL_SIGMA_PX", "PredictedLimbSphere", "predicted_center", "predicted_refit", "sunlit_sphere"]
