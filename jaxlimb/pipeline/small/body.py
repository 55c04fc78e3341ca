r"""The few-pixel body strategy of :func:`jaxlimb.pipeline.locate`: a body whose expected apparent radius is below
:data:`~jaxlimb.pipeline.frame.SMALL_RADIUS_MAX_PX` (the Sun direction known; or any body with ``shape="small"``),
measured as a whole: the blurred lit disc at the hints' phase, fitted to a window of pixels about
it (:mod:`jaxlimb.pipeline.small.fit`).  The centre of brightness corrected for the phase
(:mod:`jaxlimb.pipeline.small.blob`, GIANT's moment algorithm) answers when that fit fails or when the two centres
disagree beyond both covariances (:func:`disagreement_chi2`).

The stages: **prepare** the frame in float64; **candidates** the blob (Check "no body"); **limb pixels** the window;
**edge fit** the disc fit, or the centre of brightness; **profile refit** none (the disc fit is the physical model);
**body-centre mapping** the disc (a circle, orthographic) stands for the sphere's image ellipse: its centre and mean
radius mapped exactly to the image of the body centre, the on-axis-equivalent radius and the range
(:func:`small_center`), the line of sight through the centre; **checks** levels, PSF width, the centre's sigma.

Accuracy: ``benchmarks/small_bodies.py`` (independent renders of Moon-like spheres of radius 1-10 px).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, final

import jax.numpy as jnp
import numpy as np

from ..._validate import check_center_sigma
from ...errors import ConfigError, ConvergenceError
from ...fitting import FitResult, LimbFit
from ...geometry.sphere_image import image_mean_radius, sphere_from_circle_fit
from ...numerics import numerical_jacobian
from ..checks import check_edge_width, check_levels
from ..frame import DEFAULT_RADIUS_UNCERTAINTY, expected_radius_px, frame_mask
from ..result import LimbMeasurement
from ..stages import Body, BodyCenter, Covariance, FitData, Frame, Levels, RefineResult
from .blob import BlobCandidates, find_blob, phase_corrected
from .fit import SmallPixels, disc_at, fit_small_disc, offset_and_gradients, sun_geometry, window_pixels


#: Probability under which the disc fit and the centre of brightness are taken to agree (:func:`disagreement_chi2`):
#: a right disc fit falls back at most once in a thousand frames (the statistic is bounded from below).
AGREEMENT_PROBABILITY = 0.999


@dataclass(frozen=True)
class SmallEdge:
    """The measurement of the blob: the result, how it was made (``"disc"`` or ``"moments"``) and what to report."""

    result: RefineResult
    method: str
    info: dict[str, Any] = field(default_factory=dict)


def small_candidates(frame: Frame) -> BlobCandidates:
    """Stage "candidates": the blob (:func:`~jaxlimb.pipeline.small.blob.find_blob`) with the hints' size, as the mean
    radius of the sphere's image where the blob is (:func:`~jaxlimb.geometry.sphere_image.image_mean_radius`).

    Parameters
    ----------
    frame : Frame
        The prepared inputs; its hints give the Sun direction, expected radius and centre.

    Returns
    -------
    BlobCandidates

    Raises
    ------
    ConfigError
        The Sun direction is unknown.
    """
    h = frame.hints
    if not frame.sun_known:
        raise ConfigError("the few-pixel strategy needs the Sun direction (hints sun_dir_camera): a body of a few "
                          "pixels' centre of light lies up to half its radius sunward of its centre")
    u = (h.expected_radius_uncertainty_frac if h is not None else None) or DEFAULT_RADIUS_UNCERTAINTY
    near = h.expected_center_rc if h is not None else None
    cand = find_blob(frame.img, frame_mask(frame), expected_radius_px(frame), u, near)
    if cand.expected_radius_px is not None and frame.cam is not None:  # the image's mean radius there, off-axis
        cand = replace(cand, expected_radius_px=image_mean_radius(frame.cam.focal_px, frame.cam.principal_point_rc,
                                                                   frame.to_ideal(cand.centroid_rc),
                                                                   cand.expected_radius_px))
    frame.mark("front_end")
    return cand


def moments_result(frame: Frame, cand: BlobCandidates, pix: SmallPixels, reason: str) -> SmallEdge:
    """The centre of brightness corrected for the phase, as a :class:`~jaxlimb.pipeline.stages.RefineResult` over
    ``(r0, c0)`` (the fallback of :func:`small_edge`).

    Parameters
    ----------
    frame : Frame
        The prepared inputs.
    cand : BlobCandidates
        The blob; its radius comes from its second moment when the hints give none.
    pix : SmallPixels
        The window.
    reason : str
        Why the disc fit was not used (empty when it was), reported as ``fallback_reason``.

    Returns
    -------
    SmallEdge
        Method ``"moments"``: the corrected centre (px) and its covariance (px^2) over ``(r0, c0)``.
    """
    sun = sun_geometry(frame, cand.centroid_rc)
    a = cand.expected_radius_px
    if a is None:  # the blob's second moment less a ~1 px PSF: a uniform disc's variance per axis is a^2/4
        a = 2.0 * math.sqrt(max(cand.second_moment - 0.64 - 1.0 / 12.0, 0.25))
        cand = replace(cand, expected_radius_px=a, radius_uncertainty=0.5)
    p = disc_at(cand, pix, cand.centroid_rc, a, 0.8, sun)
    off, g_a, g_l = offset_and_gradients(p)
    center, C = phase_corrected(cand, off, g_a, g_l)
    p = p.replace(r0=center[0], c0=center[1])
    fit = LimbFit(params=p, free=("r0", "c0"), covariance=jnp.asarray(C), sigma2=jnp.asarray(cand.noise ** 2),
                  rms=jnp.asarray(cand.noise), n_pixels=jnp.asarray(int(pix.z.size)), n_steps=jnp.asarray(0),
                  result=FitResult.successful, solver="moments")
    rr = RefineResult(fit, FitData(pix.coords, pix.z, None, 0.0, 1.0), 0, ("a", "sigma", "amp", "ymin"))
    info = {"fallback_reason": reason, "centre_of_brightness_rc": list(cand.centroid_rc),
            "phase_offset_rc": [float(v) for v in off]}
    return SmallEdge(rr, "moments", info)


def small_edge(frame: Frame, cand: BlobCandidates, pix: SmallPixels) -> SmallEdge:
    """Stage "edge fit": the disc fit; the centre of brightness corrected for the phase when it does not converge
    (reported beside the disc fit's answer otherwise).

    Parameters
    ----------
    frame : Frame
        The prepared inputs.
    cand : BlobCandidates
        The blob.
    pix : SmallPixels
        The window.

    Returns
    -------
    SmallEdge
        Method ``"disc"`` or ``"moments"``.
    """
    try:
        rr, info = fit_small_disc(frame, cand, pix)
    except ConvergenceError as e:
        return moments_result(frame, cand, pix, str(e))
    frame.mark("refine")
    mom = moments_result(frame, cand, pix, "")
    p, C = mom.result.fit.params, np.asarray(mom.result.fit.covariance)
    t = disagreement_chi2(rr, mom.result)
    info = {**info, "moments_rc": [float(p.r0), float(p.c0)], "moments_cov": C.tolist(),
            "phase_offset_rc": mom.info["phase_offset_rc"], "disc_vs_moments_chi2": t}
    if t > -2.0 * math.log(1.0 - AGREEMENT_PROBABILITY):  # chi-square's quantile for 2 dof, in closed form
        d = rr.fit.params
        reason = (f"the disc fit's centre ({float(d.r0):.4g}, {float(d.c0):.4g}) disagrees with the phase-corrected "
                  f"centre of brightness beyond both covariances (chi-square {t:.3g}, 2 dof)")
        return SmallEdge(mom.result, "moments", {**mom.info, "fallback_reason": reason,
                                                 "disc_rc": [float(d.r0), float(d.c0)], "disc_vs_moments_chi2": t})
    return SmallEdge(rr, "disc", info)


def disagreement_chi2(disc: RefineResult, moments: RefineResult) -> float:
    r"""Hausman's (1978) test of the disc fit against the phase-corrected centre of brightness: both estimate the centre
    from the same pixels, the moments with fewer assumptions (no fitted shape, no solver), so a disc fit whose centre
    lies outside their joint uncertainty measured something else (a fit that traded its centre for its amplitude on a
    faint crescent).  The two are positively correlated, so ``C_disc + C_moments`` bounds the difference's covariance
    from above and the statistic from below: the test errs toward the disc fit.

    Parameters
    ----------
    disc : RefineResult
        The disc fit (``r0``, ``c0`` its first free parameters, its covariance with the consider terms).
    moments : RefineResult
        :func:`moments_result`'s.

    Returns
    -------
    float
        :math:`d^\top (C_d + C_m)^{-1} d` over the two centres' difference ``d``; when both are right, at most
        chi-square with 2 degrees of freedom.
    """
    pd, pm = disc.fit.params, moments.fit.params
    d = np.array([float(pd.r0) - float(pm.r0), float(pd.c0) - float(pm.c0)])
    V = np.asarray(disc.fit.covariance, float)[:2, :2] + np.asarray(moments.fit.covariance, float)
    return float(d @ np.linalg.solve(V, d))


def small_report(cand: BlobCandidates, edge: SmallEdge) -> dict[str, Any]:
    """The intermediate values worth reporting (``extras``).

    Parameters
    ----------
    cand : BlobCandidates
        The blob.
    edge : SmallEdge
        The measurement (:func:`small_edge`).

    Returns
    -------
    dict
        Name -> JSON-ready value.
    """
    return {"small_body": {"method": edge.method, "peak_rc": list(cand.peak_rc), "snr_peak": cand.snr,
                           "centre_of_brightness_rc": list(cand.centroid_rc), "sky": cand.sky, "noise": cand.noise,
                           "expected_radius_px": cand.expected_radius_px, **edge.info},
            "n_outliers": 0}


def small_center(frame: Frame, final: RefineResult) -> BodyCenter:
    """Stage "body-centre mapping" (module docstring): off the boresight a sphere's image is an ellipse elongated
    radially, whose mean radius exceeds the on-axis-equivalent radius ``f tan(alpha)`` by about ``3/4 theta^2``
    (``theta`` the centre's angle from the boresight); the disc's centre and radius are that ellipse's centre and
    mean radius, mapped exactly to the image of the body centre, ``f tan(alpha)`` and the range ``R / sin(alpha)``
    (:func:`~jaxlimb.geometry.sphere_image.sphere_from_circle_fit`, in ideal pixels).

    Parameters
    ----------
    frame : Frame
        The prepared inputs; its camera gives the map and the LOS and, with the body radius, the range.
    final : RefineResult
        The fit that answers.

    Returns
    -------
    BodyCenter
        Centre ``(row, col)`` (px), radius (px), LOS, range (km, when the radius was fitted) and the map's Jacobian.
    """
    p = final.fit.params
    a_free = "a" in final.fit.free
    outputs = ("center_r", "center_c", "radius") if a_free else ("center_r", "center_c")
    params = ("r0", "c0", "a") if a_free else ("r0", "c0")
    x0 = np.array([float(p.r0), float(p.c0), float(p.a)])
    if frame.cam is None:
        return BodyCenter((x0[0], x0[1]), x0[2], None, None, None, outputs, params, np.eye(len(params)))
    cam = frame.cam

    def mapped(x: np.ndarray) -> np.ndarray:
        sph = sphere_from_circle_fit(cam.focal_px, cam.principal_point_rc, frame.to_ideal(x[:2]), x[2])
        return np.array([*frame.to_observed(sph.body_center_rc), sph.radius_equivalent_px, sph.alpha_rad])

    out = mapped(x0)
    c = (float(out[0]), float(out[1]))
    los = tuple(float(v) for v in cam.los(np.asarray(c)))
    rng = float(frame.body_radius_km / math.sin(out[3])) if a_free and frame.body_radius_km is not None else None
    jac = numerical_jacobian(lambda x: mapped(x)[: len(outputs)], x0, 1e-4)[:, : len(params)]
    return BodyCenter(c, float(out[2]), None, los, rng, outputs, params, jac)


@final
@dataclass(frozen=True)
class SmallBody(Body[SmallPixels, SmallEdge]):
    """A few-pixel body measured as a whole (module docstring)."""

    name: ClassVar[str] = "small body"

    def prepare(self, frame: Frame) -> Frame:
        """The frame with its image in float64.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        Frame
        """
        return replace(frame, img=np.asarray(frame.img, dtype=np.float64))

    def candidates(self, frame: Frame) -> BlobCandidates:
        """Stage 2: the blob and Check "no body" (:func:`small_candidates`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        BlobCandidates
            Peak, centre of brightness, sky and noise (DN), expected radius (px).
        """
        return small_candidates(frame)

    def limb_pixels(self, frame: Frame, cand: BlobCandidates) -> SmallPixels:
        """Stage 3: the window about the blob (:func:`~jaxlimb.pipeline.small.fit.window_pixels`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : BlobCandidates
            The blob (:meth:`candidates`).

        Returns
        -------
        SmallPixels
            The valid pixels of the window.
        """
        return window_pixels(frame.img, frame_mask(frame), cand.peak_rc)

    def edge_fit(self, frame: Frame, cand: BlobCandidates, pixels: SmallPixels) -> SmallEdge:
        """Stage 4: the disc fit, or the centre of brightness corrected for the phase (:func:`small_edge`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : BlobCandidates
            The blob (:meth:`candidates`).
        pixels : SmallPixels
            The window (:meth:`limb_pixels`).

        Returns
        -------
        SmallEdge
            The measurement and how it was made.
        """
        return small_edge(frame, cand, pixels)

    def report(self, frame: Frame, cand: BlobCandidates, edge: SmallEdge) -> dict[str, Any]:
        """The blob's and the fit's numbers for ``extras`` (:func:`small_report`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : BlobCandidates
            The blob (:meth:`candidates`).
        edge : SmallEdge
            The disc fit or the centre of brightness (:meth:`edge_fit`).

        Returns
        -------
        dict
            Name -> JSON-ready value.
        """
        return small_report(cand, edge)

    def refit(self, frame: Frame, cand: BlobCandidates, edge: SmallEdge, extras: dict[str, Any]) -> RefineResult:
        """Stage "profile refit": none, the disc fit is the physical model.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : BlobCandidates
            The blob (:meth:`candidates`).
        edge : SmallEdge
            The disc fit or the centre of brightness (:meth:`edge_fit`).
        extras : dict
            The report (unchanged).

        Returns
        -------
        RefineResult
            ``edge.result``.
        """
        return edge.result

    def body_center(self, frame: Frame, edge: SmallEdge, final: RefineResult) -> BodyCenter:
        """Stage "body-centre mapping": the disc's centre is the body's (:func:`small_center`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        edge : SmallEdge
            The measurement (unused: the map needs only ``final``).
        final : RefineResult
            The fit that answers (:meth:`refit`).

        Returns
        -------
        BodyCenter
            Centre ``(row, col)``, radius (px), LOS, range (km) and the map's Jacobian.
        """
        return small_center(frame, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        """Stage "checks": levels, PSF width and the centre's sigma within ``max_center_sigma_px``.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        levels : Levels
            The fitted edge.
        cov : Covariance
            The reported covariance.
        """
        check_levels(levels.ymax, levels.ymin, self.name)
        check_edge_width(levels.psf_sigma_px, self.name)
        check_center_sigma(cov.block(("center_r", "center_c")), frame.opt.max_center_sigma_px)

    def iterations(self, edge: SmallEdge, final: RefineResult) -> int:
        """The solver steps of the answering fit (0 for the centre of brightness).

        Parameters
        ----------
        edge : SmallEdge
        final : RefineResult

        Returns
        -------
        int
        """
        return int(final.fit.n_steps)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """The measurement unchanged.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        meas : LimbMeasurement

        Returns
        -------
        LimbMeasurement
            ``meas``.
        """
        return meas


__all__ = ["AGREEMENT_PROBABILITY", "SmallBody", "SmallEdge", "disagreement_chi2", "small_center"]
