"""The round strategies of :func:`jaxlimb.pipeline.locate`: a sphere (lit limb: circle annulus, circular sigmoid,
lunar-Lambert profile or the sphere-shaped ESF, dark-limb check) and a self-luminous disc (the Sun: the same edge
fit, the limb-darkened disc's profile)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, final

from ...errors import CheckFailed, NoBodyError
from ..frame import candidates, outline_candidates, small_possible
from ..options import BodyShape
from ..report import check_physical
from ..result import LimbMeasurement
from ..small.body import SmallBody
from ..stages import Body, BodyCenter, Covariance, EdgeFit, Frame, Levels, LimbPixels, RefineResult
from .dark_limb import check_measurement
from .edge import check_edge, edge_fit, edge_report, limb_pixels
from .corona import RingPixels, corona_edge, limb_brightened, ring_pixels
from .refit import disc_center_of, disc_image, disc_refit, sphere_center_of, sphere_refit


@final
@dataclass(frozen=True)
class Sphere(Body[LimbPixels, EdgeFit]):
    """A sphere measured on its lit limb (module docstring); ``physical``: the lunar-Lambert profile refit is tried."""

    physical: bool
    name: ClassVar[str] = "sphere"

    def prepare(self, frame: Frame) -> Frame:
        """The frame unchanged (a round body is measured on the observed grid).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        Frame
            ``frame``.
        """
        return frame

    def candidates(self, frame: Frame) -> Any:
        """Stage 2: the chosen front end, the other as fallback (:func:`jaxlimb.pipeline.frame.candidates`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        LimbCandidates
            Limb points, initial circle, lit direction (Checks 1-4 passed).
        """
        return candidates(frame)

    def limb_pixels(self, frame: Frame, cand: Any) -> LimbPixels:
        """Stage 3: the annulus on the lit side (:func:`~jaxlimb.pipeline.sphere.edge.limb_pixels`; the shorter lit arc
        of the profile refit accepted when ``physical``).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).

        Returns
        -------
        LimbPixels
            The annulus on the lit side and its window.
        """
        return limb_pixels(frame, cand, self.physical)

    def edge_fit(self, frame: Frame, cand: Any, pixels: LimbPixels) -> EdgeFit:
        """Stage 4: the circular sigmoid (Eq. 16 of the illuminated-ellipsoid paper) on the annulus
        (:func:`~jaxlimb.pipeline.sphere.edge.edge_fit`), then Checks 5, 1, 3/4 and 4
        (:func:`~jaxlimb.pipeline.sphere.edge.check_edge`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).
        pixels : LimbPixels
            The annulus (:meth:`limb_pixels`).

        Returns
        -------
        EdgeFit
            The fit, its annulus, the arc and the jump with its limit.
        """
        return check_edge(frame, cand, edge_fit(frame, pixels))

    def report(self, frame: Frame, cand: Any, edge: EdgeFit) -> dict[str, Any]:
        """The initial circle, circle fit, annulus and checks' numbers for ``extras``
        (:func:`~jaxlimb.pipeline.sphere.edge.edge_report`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).
        edge : EdgeFit
            The checked circular-sigmoid fit (:meth:`edge_fit`).

        Returns
        -------
        dict
            Name -> JSON-ready value.
        """
        return edge_report(frame, cand, edge)

    def refit(self, frame: Frame, cand: Any, edge: EdgeFit, extras: dict[str, Any]) -> RefineResult:
        """Stage "profile refit": the lunar-Lambert limb profile when ``physical``; if not (or rejected) the
        sphere-shaped ESF with a camera, else the circle; ``model="ellipse"``: then the free ESF
        (:func:`~jaxlimb.pipeline.sphere.refit.sphere_refit`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).
        edge : EdgeFit
            The checked circular-sigmoid fit (:meth:`edge_fit`).
        extras : dict
            The report; the refit adds its own numbers to it.

        Returns
        -------
        RefineResult
            The answering fit: the refit, or ``edge.circ`` when none applies.
        """
        return sphere_refit(frame, cand, edge, self.physical, extras)

    def body_center(self, frame: Frame, edge: EdgeFit, final: RefineResult) -> BodyCenter:
        """Stage "body-centre mapping": the fitted limb -> the sphere's centre image, radius, LOS and range (exact with
        a camera; :func:`~jaxlimb.pipeline.sphere.refit.sphere_center_of`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        edge : EdgeFit
            The edge fit (unused: the map needs only ``final``).
        final : RefineResult
            The fit that answers (:meth:`refit`).

        Returns
        -------
        BodyCenter
            Centre ``(row, col)``, radius (px), LOS, range (km) and the map's Jacobian.
        """
        return sphere_center_of(frame, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        """Stage "checks": the fit is physical (levels, edge blur) and the centre's sigma within
        ``max_center_sigma_px`` (:func:`~jaxlimb.pipeline.report.check_physical`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        levels : Levels
            The fitted edge.
        cov : Covariance
            The reported covariance.
        """
        check_physical(frame, levels, cov, self.name)

    def iterations(self, edge: EdgeFit, final: RefineResult) -> int:
        """The solver steps of the answer (:func:`round_iterations`).

        Parameters
        ----------
        edge : EdgeFit
        final : RefineResult

        Returns
        -------
        int
        """
        return round_iterations(edge, final)

    def instead(self, frame: Frame, refusal: CheckFailed) -> Body | None:
        """The few-pixel strategy (:class:`~jaxlimb.pipeline.small.body.SmallBody`) when this one was chosen
        automatically, refused the frame for another reason than no body, and the few-pixel model can hold the disc the
        hints expect (:func:`~jaxlimb.pipeline.frame.small_possible`): a disc a few pixels above the switch radius has a
        limb of a few dozen pixels, at times too few for the front end's consensus; the whole-disc model needs none.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        refusal : CheckFailed
            This strategy's refusal.

        Returns
        -------
        SmallBody or None
        """
        if frame.opt.shape == BodyShape.AUTO and not isinstance(refusal, NoBodyError) and small_possible(frame):
            return SmallBody()
        return None

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """The dark-limb check on the measured circle (:func:`~jaxlimb.pipeline.sphere.dark_limb.check_measurement`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        meas : LimbMeasurement

        Returns
        -------
        LimbMeasurement
        """
        return check_measurement(frame, meas)


@final
@dataclass(frozen=True)
class Disc(Body[LimbPixels, EdgeFit]):
    """A self-luminous limb-darkened disc (the Sun): the sphere's front end and edge fit, the limb-darkened disc's
    profile on a full annulus, its centre the body's."""

    name: ClassVar[str] = "disc"

    def prepare(self, frame: Frame) -> Frame:
        """The frame unchanged (a round body is measured on the observed grid).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        Frame
            ``frame``.
        """
        return frame

    def candidates(self, frame: Frame) -> Any:
        """Stage 2: the outline of the disc's bright region, or the chosen front end and the other as fallback
        whatever the region when the outline does not define the disc (:func:`jaxlimb.pipeline.frame.
        outline_candidates`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        LimbCandidates
            Limb points, initial circle, lit direction (Checks 1-4 passed).
        """
        return outline_candidates(frame)

    def limb_pixels(self, frame: Frame, cand: Any) -> LimbPixels:
        """Stage 3: the annulus on the lit side (:func:`~jaxlimb.pipeline.sphere.edge.limb_pixels`, sigmoid arc limit);
        the whole annulus for the EUV corona's limb (:func:`~jaxlimb.pipeline.sphere.corona.ring_pixels`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).

        Returns
        -------
        LimbPixels
            The annulus on the lit side and its window (all round for the corona).
        """
        opt, img = frame.opt, disc_image(frame)
        if opt.profile == "corona" or (opt.profile == "auto" and limb_brightened(img, cand.center_rc, cand.radius)):
            return ring_pixels(img, cand)
        return limb_pixels(frame, cand, False)

    def edge_fit(self, frame: Frame, cand: Any, pixels: LimbPixels) -> EdgeFit:
        """Stage 4: the circular sigmoid (Eq. 16 of the illuminated-ellipsoid paper) on the annulus
        (:func:`~jaxlimb.pipeline.sphere.edge.edge_fit`), then Checks 5, 1, 3/4 and 4
        (:func:`~jaxlimb.pipeline.sphere.edge.check_edge`); on the pixels of a disc brightest at its limb (the EUV,
        or ``profile="corona"``: :class:`~jaxlimb.pipeline.sphere.corona.RingPixels`), the corona's limb
        (:func:`~jaxlimb.pipeline.sphere.corona.corona_edge`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).
        pixels : LimbPixels
            The annulus (:meth:`limb_pixels`).

        Returns
        -------
        EdgeFit
            The fit, its annulus, the arc and the jump with its limit.
        """
        if isinstance(pixels, RingPixels):  # the limb-pixel stage found the disc brightest at its limb
            return corona_edge(frame, disc_image(frame), cand, pixels)
        return check_edge(frame, cand, edge_fit(frame, pixels))

    def report(self, frame: Frame, cand: Any, edge: EdgeFit) -> dict[str, Any]:
        """The initial circle, circle fit, annulus and checks' numbers for ``extras``
        (:func:`~jaxlimb.pipeline.sphere.edge.edge_report`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).
        edge : EdgeFit
            The checked circular-sigmoid fit (:meth:`edge_fit`).

        Returns
        -------
        dict
            Name -> JSON-ready value.
        """
        return edge_report(frame, cand, edge)

    def refit(self, frame: Frame, cand: Any, edge: EdgeFit, extras: dict[str, Any]) -> RefineResult:
        """Stage "profile refit": the limb-darkened disc's profile on the full annulus
        (:func:`~jaxlimb.pipeline.sphere.refit.disc_refit`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : LimbCandidates
            The front end's answer (:meth:`candidates`).
        edge : EdgeFit
            The checked circular-sigmoid fit (:meth:`edge_fit`).
        extras : dict
            The report; the refit adds its own numbers to it.

        Returns
        -------
        RefineResult
            The limb-darkened disc's fit and its pixels.
        """
        return disc_refit(frame, edge, extras)

    def body_center(self, frame: Frame, edge: EdgeFit, final: RefineResult) -> BodyCenter:
        """Stage "body-centre mapping": the disc's centre is the body's; range from the radius with a camera
        (:func:`~jaxlimb.pipeline.sphere.refit.disc_center_of`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        edge : EdgeFit
            The edge fit (unused: the map needs only ``final``).
        final : RefineResult
            The fit that answers (:meth:`refit`).

        Returns
        -------
        BodyCenter
            Centre ``(row, col)``, radius (px), LOS, range (km) and the map's Jacobian.
        """
        return disc_center_of(frame, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        """Stage "checks": the fit is physical (levels, edge blur) and the centre's sigma within
        ``max_center_sigma_px`` (:func:`~jaxlimb.pipeline.report.check_physical`).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        levels : Levels
            The fitted edge.
        cov : Covariance
            The reported covariance.
        """
        check_physical(frame, levels, cov, self.name)

    def iterations(self, edge: EdgeFit, final: RefineResult) -> int:
        """The solver steps of the answer (:func:`round_iterations`).

        Parameters
        ----------
        edge : EdgeFit
        final : RefineResult

        Returns
        -------
        int
        """
        return round_iterations(edge, final)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """The measurement unchanged (a self-luminous disc has no dark limb).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        meas : LimbMeasurement

        Returns
        -------
        LimbMeasurement
        """
        return meas


def round_iterations(edge: EdgeFit, final: RefineResult) -> int:
    """The edge fit's steps, and the refit's when the answer is a refit (not the edge fit with a widened covariance).

    Parameters
    ----------
    edge : EdgeFit
        The circular-sigmoid fit.
    final : RefineResult
        The answering fit (``edge.circ`` or a refit).

    Returns
    -------
    int
        Total solver steps.
    """
    return int(edge.circ.fit.n_steps) + (int(final.fit.n_steps) if final.data is not edge.circ.data else 0)


__all__ = ["Disc", "Sphere", "round_iterations"]
