"""The round strategies of :func:`jaxlimb.pipeline.locate`: a sphere (lit limb: circle annulus, circular sigmoid,
lunar-Lambert profile or the sphere-shaped ESF, dark-limb check) and a self-luminous disc (the Sun: the same edge
fit, the limb-darkened disc's profile)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, final

from ..frame import candidates
from ..report import check_physical
from ..result import LimbMeasurement
from ..stages import Body, BodyCenter, Covariance, EdgeFit, Frame, Levels, LimbPixels, RefineResult
from .dark_limb import check_measurement
from .edge import check_edge, edge_fit, edge_report, limb_pixels
from .refit import disc_center_of, disc_refit, sphere_center_of, sphere_refit


@final
@dataclass(frozen=True)
class Sphere(Body[LimbPixels, EdgeFit]):
    """A sphere measured on its lit limb (module docstring); ``physical``: the lunar-Lambert profile refit is tried."""

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


__all__ = ["Disc", "Sphere", "round_iterations"]
