r"""The ellipsoid strategy of :func:`jaxlimb.pipeline.locate` (the Earth; any spheroid): the stages that
differ from a sphere's.  The method (limb cone, elliptical edge with interior ramp, physical profile,
Earth offset and range iteration of Mortari, D'Souza & Zanetti 2016 §IV, Fig. 2) is described in
:mod:`jaxlimb.pipeline.ellipsoid`, which holds its geometry (:func:`earth_position_from_ellipse`).

* **prepare**: a camera is required (the range needs it); with lens distortion the frame is resampled
  onto the ideal pixel grid (the limb is a conic only there) and ``finish`` maps the centre and its
  covariance back through the distortion's Jacobian.
* **candidates**: the shared front end; when it fails on the radius or the outliers (its circle on cloud
  edges), the range prior's radius behind the disc's sunward extreme (:func:`blob_candidates`).  A body other than
  the Earth whose limb the hints predict (SPICE) starts from the predicted-limb front end instead
  (:mod:`jaxlimb.pipeline.ellipsoid.predicted_start`).
* **limb pixels**: the lit window from the Sun direction (else the front end's arc) less
  ``arc_margin_deg`` at each horn (:class:`~jaxlimb.errors.ArcTooShortError` when nothing is left),
  and the band of half-width ``band_px`` about the current ellipse (:func:`~jaxlimb.pipeline.ellipsoid.band.band_pixels`).
  The ellipse is the limb traced against the sky (:mod:`jaxlimb.pipeline.ellipsoid.trace`:
  the outermost edge along rays, not the front end's circle, which lies on cloud edges 7-19 px off on cloudy
  frames); on an albedo-patchy limb (clouds) the band is level-normalised per ray, rays with a cloud edge inside
  the band are left out, the edge is a plain step, the uniform-albedo profile is not fitted and the traced points'
  cluster-robust spread is added to the covariance as model error.  With the attitude known, the rays' own
  known-shape ellipse replaces the band fit when the band fit does not converge or leaves the rays' 95 % region
  (:func:`patchy_geometry`), and the two estimates' difference is added to the covariance; a glow above a cloudy
  limb lifts the dim rays' edges more than the bright ones', and that lift (``c / A_ray``) is fitted beside the rays'
  ellipse when it is significant (:func:`_fit_rays`).  A front-end circle
  outside the range prior's 1-sigma radius band (on cloud edges) is replaced by the disc-and-prior start.
* **edge fit**: the elliptical sigmoid with interior ramp (:data:`jaxlimb.models.ELLIPSE_RAMP`), ``rho,
  theta`` predicted from the limb cone at the current position (``R_body_to_camera`` known; else or with
  ``model="ellipse"`` free), repeated while the prediction moves the ellipse; Checks 1, 3/4 (radius in the
  prior's band), 4 and 5 (jump from the front end's circle) as for a sphere.
* **profile refit**: the lunar-Lambert profile on the same pixels (Sun direction known), widened by a glow above
  the limb when the score test of the Moon's glow gate asks for it (:func:`~jaxlimb.pipeline.ellipsoid.profile.widen_glow_ellipsoid`).
* **body-centre mapping**: the range iteration; the covariance of ``(center_r, center_c, range_km)`` through
  its central-difference Jacobian; with a free ellipse the unsigned centre offset as a model error.

``estimate_k=False`` (the papers' fixed-``k`` sphere setting) is refused: the ellipsoid's edge model
estimates its kernel with the ramp.  ``model="ellipse"`` frees ``rho, theta``.  ``compute_crlb`` as for
every body (:func:`jaxlimb.pipeline.report.crlb`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, ClassVar, final

import numpy as np

from ...imaging.undistort import pinhole_of, undistort_image
from ...numerics import numerical_jacobian
from ..report import check_physical
from ..result import LimbMeasurement, covariance_block
from ..stages import Body, BodyCenter, Covariance, EllipsePixels, EllipsoidEdge, Frame, Levels, RefineResult
from .center import ellipsoid_center
from .edge import ellipsoid_edge
from .model import EllipsoidModel, earth_hints
from .predicted_start import spheroid_candidates
from .profile import fit_profile_ellipsoid, floor_center_var
from .start import ellipse_pixels


def ellipsoid_prepare(frame: Frame) -> Frame:
    """Stage "prepare" of the ellipsoid: the hints name the Earth when they name no body; with lens distortion the
    image is resampled onto the ideal (pinhole) grid, where the limb is a conic, and the observed camera kept for
    ``finish``.

    Parameters
    ----------
    frame : Frame
        The validated inputs.

    Returns
    -------
    Frame
        ``frame`` with its hints completed and, for a distorted camera, the ideal image, its pinhole camera and
        ``observed_cam``.
    """
    cam = frame.cam
    if frame.hints is None or frame.hints.body is None:
        frame = replace(frame, hints=earth_hints(frame.hints))
    if cam is None or not cam.has_distortion:
        return frame

    return replace(frame, img=undistort_image(frame.img, cam), cam=pinhole_of(cam), observed_cam=cam)


def ellipsoid_report(body: EllipsoidModel, frame: Frame, cand: Any, edge: EllipsoidEdge) -> dict[str, Any]:
    """The intermediate values of the ellipsoid's first stages, for ``extras``.

    Parameters
    ----------
    body : EllipsoidModel
        The body (``free``, ``atmosphere_km``).
    frame : Frame
        The frame (whether the Sun direction is known).
    cand : Any
        The front end's candidates (initial circle, prior).
    edge : EllipsoidEdge
        The edge fit.

    Returns
    -------
    dict
        The initial circle, the edge fit (model, fit history, ellipse centre and semi-axes in px, range in km),
        the range prior, the jump of Check 5 and its limit (px), and the prior's source.
    """
    prior = cand.info.get("prior")
    return {"initial_circle": {"center_rc": list(cand.center_rc), "radius_px": cand.radius,
                               "n_points": cand.n_points},
            "edge_fit": {"model": edge.final.fit.params.__class__.__name__, "fits": edge.history,
                         "ellipse_center_rc": list(edge.fitted[0]), "semi_axes_px": list(edge.fitted[1]),
                         "range_km": float(np.linalg.norm(edge.p))},
            "fits": edge.history, "range_prior_km": edge.pixels.range_prior_km, "free_ellipse": body.free,
            "atmosphere_km": body.atmosphere_km, "jump_px": edge.jump_px, "jump_limit_px": edge.jump_limit_px,
            "sun_direction_known": frame.sun_known, "prior_source": prior.source if prior is not None else None}


def distorted_back(frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
    """Stage "finish" of the ellipsoid: with a distorted camera, ``center_rc`` and its covariance rows mapped to the
    observed image.

    Parameters
    ----------
    frame : Frame
        The frame; ``observed_cam`` is the distorted camera (``None``: nothing to map).
    meas : LimbMeasurement
        The measurement in ideal (pinhole) pixels.

    Returns
    -------
    LimbMeasurement
        The centre, the selected pixels and the ``center_r, center_c`` rows and columns of the covariance mapped
        through the distortion (its Jacobian by central differences); ``meas`` itself without distortion.
    """
    cam = frame.observed_cam
    if cam is None:
        return meas
    c_id = np.asarray(meas.center_rc, float)
    Jd = numerical_jacobian(lambda x: cam.distort(x), c_id, 1e-3)
    names = list(meas.covariance)
    P = covariance_block(meas.covariance, names)
    T = np.eye(len(names))
    idx = [names.index("center_r"), names.index("center_c")]
    T[np.ix_(idx, idx)] = Jd
    P = T @ P @ T.T
    cov = {a: {b: float(P[i, j]) for j, b in enumerate(names)} for i, a in enumerate(names)}
    c_obs = cam.distort(c_id)
    pix = None if meas.selected_pixels_rc is None else cam.distort(np.asarray(meas.selected_pixels_rc, float))
    extras = {**meas.extras, "ellipse_frame": "ideal (undistorted) pixels", "undistorted_image": True}
    return replace(meas, center_rc=(float(c_obs[0]), float(c_obs[1])), covariance=cov, selected_pixels_rc=pix,
                   extras=extras)


@final
@dataclass(frozen=True)
class Ellipsoid(Body[EllipsePixels, EllipsoidEdge]):
    """The ellipsoid strategy (module docstring) of the body :class:`EllipsoidModel`."""

    model: EllipsoidModel
    name: ClassVar[str] = "ellipsoid"

    @classmethod
    def for_frame(cls, frame: Frame) -> "Ellipsoid":
        """The strategy for ``frame`` (:meth:`EllipsoidModel.for_frame`).

        Parameters
        ----------
        frame : Frame
            The validated inputs.

        Returns
        -------
        Ellipsoid
            The strategy with the body's model.
        """
        return cls(EllipsoidModel.for_frame(frame))

    @property
    def free(self) -> bool:
        """The ellipse's axis ratio and orientation are fitted (the attitude unknown, or ``model="ellipse"``)."""
        return self.model.free

    def prepare(self, frame: Frame) -> Frame:
        """Stage "prepare" (:func:`ellipsoid_prepare`).

        Parameters
        ----------
        frame : Frame
            The validated inputs.

        Returns
        -------
        Frame
            The frame as the ellipsoid measures it.
        """
        return ellipsoid_prepare(frame)

    def candidates(self, frame: Frame) -> Any:
        """Stage "candidates" (:func:`~jaxlimb.pipeline.ellipsoid.predicted_start.spheroid_candidates`).

        Parameters
        ----------
        frame : Frame
            The prepared frame.

        Returns
        -------
        Any
            The front end's candidates and initial circle.
        """
        return spheroid_candidates(self.model, frame)

    def limb_pixels(self, frame: Frame, cand: Any) -> EllipsePixels:
        """Stage "limb pixels" (:func:`~jaxlimb.pipeline.ellipsoid.start.ellipse_pixels`).

        Parameters
        ----------
        frame : Frame
            The prepared frame.
        cand : Any
            The candidates.

        Returns
        -------
        EllipsePixels
            Position prior, lit window and start ellipse.
        """
        return ellipse_pixels(self.model, frame, cand)

    def edge_fit(self, frame: Frame, cand: Any, pixels: EllipsePixels) -> EllipsoidEdge:
        """Stage "edge fit" (:func:`~jaxlimb.pipeline.ellipsoid.edge.ellipsoid_edge`).

        Parameters
        ----------
        frame : Frame
            The prepared frame.
        cand : Any
            The candidates.
        pixels : EllipsePixels
            The start of the fit.

        Returns
        -------
        EllipsoidEdge
            The elliptical edge fit after its checks.
        """
        return ellipsoid_edge(self.model, frame, cand, pixels)

    def report(self, frame: Frame, cand: Any, edge: EllipsoidEdge) -> dict[str, Any]:
        """The intermediate values for ``extras`` (:func:`ellipsoid_report`).

        Parameters
        ----------
        frame : Frame
            The frame.
        cand : Any
            The candidates.
        edge : EllipsoidEdge
            The edge fit.

        Returns
        -------
        dict
            The values to report.
        """
        return ellipsoid_report(self.model, frame, cand, edge)

    def refit(self, frame: Frame, cand: Any, edge: EllipsoidEdge, extras: dict[str, Any]) -> RefineResult:
        """The lunar-Lambert profile on the edge fit's pixels (Sun direction known), else the edge fit; the centre's
        variance floored at ``EllipsoidOptions.center_floor_px``.

        Parameters
        ----------
        frame : Frame
            The prepared frame.
        cand : Any
            The candidates (unused).
        edge : EllipsoidEdge
            The edge fit.
        extras : dict
            The report, to which the profile stage adds its values.

        Returns
        -------
        RefineResult
            The final fit.
        """
        return floor_center_var(fit_profile_ellipsoid(self.model, frame, edge, extras), self.model.eo.center_floor_px ** 2)

    def body_center(self, frame: Frame, edge: EllipsoidEdge, final: RefineResult) -> BodyCenter:
        """Stage "body-centre mapping" (:func:`~jaxlimb.pipeline.ellipsoid.center.ellipsoid_center`).

        Parameters
        ----------
        frame : Frame
            The prepared frame.
        edge : EllipsoidEdge
            The edge fit (unused).
        final : RefineResult
            The final fit.

        Returns
        -------
        BodyCenter
            The body centre's image, line of sight and range, with the map's Jacobian.
        """
        return ellipsoid_center(self.model, frame, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        """Stage "checks" (:func:`~jaxlimb.pipeline.report.check_physical`).

        Parameters
        ----------
        frame : Frame
            The frame (``max_center_sigma_px``).
        levels : Levels
            The fitted edge's levels and blur.
        cov : Covariance
            The measurement's covariance.
        """
        check_physical(frame, levels, cov, self.name)

    def iterations(self, edge: EllipsoidEdge, final: RefineResult) -> int:
        """The solver steps of the fits that made the answer: the edge fits, plus the profile fit when there is one.

        Parameters
        ----------
        edge : EllipsoidEdge
            The edge fit (its history of steps).
        final : RefineResult
            The final fit.

        Returns
        -------
        int
            The number of solver steps.
        """
        # the edge fit with its model-error term is the same fit (same data), the profile a second one
        return edge.n_steps + (int(final.fit.n_steps) if type(final.fit.params) is not type(edge.final.fit.params) else 0)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """Stage "finish" (:func:`distorted_back`).

        Parameters
        ----------
        frame : Frame
            The frame.
        meas : LimbMeasurement
            The measurement.

        Returns
        -------
        LimbMeasurement
            The measurement in the observed image's pixels.
        """
        return distorted_back(frame, meas)


__all__ = ["Ellipsoid"]
