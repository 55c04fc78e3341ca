r"""Body strategies of :func:`jaxlimb.pipeline.locate`: what differs between a sphere, a sphere whose limb is
predicted, a triaxial ellipsoid and a self-luminous disc, and nothing else.

Each strategy is a final class implementing the stages of the abstract :class:`~jaxlimb.pipeline.stages.Body`
(the rest of the pipeline is shared); :func:`body_strategy` picks one from the options and the hints.

=======================  ===================================  ==========================================================
strategy                 bodies                               limb, profile, body centre
=======================  ===================================  ==========================================================
``Sphere``               Moon, Europa, Enceladus, any body    circle annulus; CSF; lunar-Lambert profile or the
                         with (near) equal radii              sphere-shaped ESF; exact sphere map
``PredictedLimbSphere``  a body whose limb the hints predict  the whole limb, lit and dark, about the predicted
                         (SPICE), or larger than the frame    ellipse (shape held); the visible arc of a close body
``Ellipsoid``            Earth, Mars (spheroids)              band about the predicted limb ellipse (rho, theta
                                                              from the limb cone); ESF with interior ramp;
                                                              lunar-Lambert profile; Earth offset and range
                                                              iteration (Mortari et al. §IV, Fig. 2)
``Disc``                 the Sun                              full annulus; CSF; limb-darkened disc; its centre
=======================  ===================================  ==========================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, final

from ..errors import ConfigError
from .dark_limb import check_measurement
from .edge import check_edge, edge_fit, edge_report, limb_pixels
from .ellipsoid import Ellipsoid
from .frame import arc_only, candidates, limb_predicted
from .options import BodyShape
from .predicted_limb import PredictedLimbSphere
from .result import LimbMeasurement
from .round_body import disc_center_of, disc_refit, sphere_center_of, sphere_refit
from .report import check_physical
from .stages import Body, BodyCenter, Covariance, EdgeFit, Frame, Levels, LimbPixels, RefineResult


@final
@dataclass(frozen=True)
class Sphere(Body[LimbPixels, EdgeFit]):
    """A sphere (module table); ``physical``: the lunar-Lambert profile refit is tried."""

    physical: bool
    name: ClassVar[str] = "sphere"

    def prepare(self, frame: Frame) -> Frame:
        return frame

    def candidates(self, frame: Frame) -> Any:
        return candidates(frame)

    def limb_pixels(self, frame: Frame, cand: Any) -> LimbPixels:
        return limb_pixels(frame, cand, self.physical)

    def edge_fit(self, frame: Frame, cand: Any, pixels: LimbPixels) -> EdgeFit:
        return check_edge(frame, cand, edge_fit(frame, pixels))

    def report(self, frame: Frame, cand: Any, edge: EdgeFit) -> dict[str, Any]:
        return edge_report(frame, cand, edge)

    def refit(self, frame: Frame, cand: Any, edge: EdgeFit, extras: dict[str, Any]) -> RefineResult:
        return sphere_refit(frame, cand, edge, self.physical, extras)

    def body_center(self, frame: Frame, edge: EdgeFit, final: RefineResult) -> BodyCenter:
        return sphere_center_of(frame, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        check_physical(frame, levels, cov, self.name)

    def iterations(self, edge: EdgeFit, final: RefineResult) -> int:
        return round_iterations(edge, final)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        return check_measurement(frame, meas)


@final
@dataclass(frozen=True)
class Disc(Body[LimbPixels, EdgeFit]):
    """A self-luminous limb-darkened disc (the Sun): the sphere's front end and edge fit, the limb-darkened disc's
    profile on a full annulus, its centre the body's."""

    name: ClassVar[str] = "disc"

    def prepare(self, frame: Frame) -> Frame:
        return frame

    def candidates(self, frame: Frame) -> Any:
        return candidates(frame)

    def limb_pixels(self, frame: Frame, cand: Any) -> LimbPixels:
        return limb_pixels(frame, cand, False)

    def edge_fit(self, frame: Frame, cand: Any, pixels: LimbPixels) -> EdgeFit:
        return check_edge(frame, cand, edge_fit(frame, pixels))

    def report(self, frame: Frame, cand: Any, edge: EdgeFit) -> dict[str, Any]:
        return edge_report(frame, cand, edge)

    def refit(self, frame: Frame, cand: Any, edge: EdgeFit, extras: dict[str, Any]) -> RefineResult:
        return disc_refit(frame, edge, extras)

    def body_center(self, frame: Frame, edge: EdgeFit, final: RefineResult) -> BodyCenter:
        return disc_center_of(frame, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        check_physical(frame, levels, cov, self.name)

    def iterations(self, edge: EdgeFit, final: RefineResult) -> int:
        return round_iterations(edge, final)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        return meas


def round_iterations(edge: EdgeFit, final: RefineResult) -> int:
    """The circle fit's steps, and the refit's when one answered."""
    return int(edge.circ.fit.n_steps) + (int(final.fit.n_steps) if final is not edge.circ else 0)


def _lunar_profile_wanted(frame: Frame) -> bool:
    """``profile="auto"``: the physical profile for a sunlit body whose Sun direction is known (circle model,
    ``k`` estimated; the papers' fixed-``k`` setting, Table 1, is a sigmoid experiment); else as asked."""
    opt, h = frame.opt, frame.hints
    if opt.profile != "auto":
        return opt.profile == "lunar-lambert"
    return opt.model == "circle" and opt.estimate_k and frame.sun_known and h is not None and h.body != "sun"


def _shape(frame: Frame) -> BodyShape:
    opt, h = frame.opt, frame.hints
    if opt.shape != BodyShape.AUTO:
        return opt.shape
    if opt.profile == "limb-darkened" or (opt.profile == "auto" and opt.model == "circle" and opt.estimate_k
                                          and h is not None and h.body == "sun"):
        return BodyShape.DISC
    if h is not None and h.body == "earth":
        return BodyShape.ELLIPSOID
    return BodyShape.SPHERE


def body_strategy(frame: Frame) -> Body:
    """The strategy for the frame: ``LocateOptions.shape``, or from the hints' body (module table); a sphere whose
    limb the hints predict (camera, range, radii, expected centre: SPICE) is measured on its whole limb, one whose
    expected disc exceeds the frame on its visible arc."""
    shape = _shape(frame)
    if shape == BodyShape.DISC:
        if frame.opt.profile not in ("auto", "limb-darkened"):
            raise ConfigError(f"the disc strategy fits the limb-darkened disc; profile = {frame.opt.profile!s} is "
                              "not available for it")
        return Disc()
    if shape == BodyShape.ELLIPSOID:
        return Ellipsoid.for_frame(frame)
    if frame.opt.profile == "limb-darkened":
        raise ConfigError("profile = 'limb-darkened' is the disc strategy's (shape = 'disc' or hints body 'sun')")
    if limb_predicted(frame) or arc_only(frame):
        return PredictedLimbSphere(arc=not limb_predicted(frame))
    return Sphere(physical=_lunar_profile_wanted(frame))


__all__ = ["Disc", "Sphere", "body_strategy", "round_iterations"]
