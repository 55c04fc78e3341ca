r"""Body strategies of :func:`jaxlimb.pipeline.locate`: what differs between a sphere, a triaxial ellipsoid and a
self-luminous disc, and nothing else.

Each strategy supplies four stages (the rest of the pipeline is shared):

* ``limb_pixels(frame, cand)`` -- which pixels are the lit limb (the band/selection stage);
* ``edge_fit(frame, cand, pixels)`` -- the sigmoid edge fit and Checks 5, 1, 3/4, 4 on it;
* ``refit(frame, cand, edge, extras)`` -- the physical profile refit (lunar-Lambert limb; limb-darkened disc);
* ``body_center(frame, final)`` -- fitted limb -> body-centre image, radius / range, with its Jacobian.

=============  ===================================  ====================================================
strategy       bodies                               limb, profile, body centre
=============  ===================================  ====================================================
``Sphere``     Moon, Europa, Enceladus, any body    circle annulus; CSF; lunar-Lambert profile or the
               with (near) equal radii              sphere-shaped ESF; exact sphere map
``Ellipsoid``  Earth, Mars (spheroids)              band about the predicted limb ellipse (rho, theta
                                                    from the limb cone); ESF with interior ramp;
                                                    lunar-Lambert profile; Earth offset and range
                                                    iteration (Mortari et al. §IV, Fig. 2)
``Disc``       the Sun                              full annulus; CSF; limb-darkened disc; its centre
=============  ===================================  ====================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..errors import ConfigError
from .edge import EdgeFit, LimbPixels, check_edge, edge_fit, edge_report, limb_pixels
from .frame import Frame, candidates
from .geometry import BodyCenter
from .options import BodyShape
from .refine import RefineResult
from .result import LimbMeasurement
from .round_body import disc_center_of, disc_refit, sphere_center_of, sphere_refit


@dataclass(frozen=True)
class Sphere:
    """A sphere (module table); ``physical``: the lunar-Lambert profile refit is tried."""

    physical: bool
    name: str = "sphere"

    def prepare(self, frame: Frame) -> Frame:
        return frame

    def candidates(self, frame: Frame) -> Any:
        return candidates(frame)

    def limb_pixels(self, frame: Frame, cand: Any) -> LimbPixels:
        return limb_pixels(frame, cand, self.physical)

    def edge_fit(self, frame: Frame, cand: Any, pixels: LimbPixels) -> EdgeFit:
        return check_edge(frame, cand, edge_fit(frame, pixels))

    def refit(self, frame: Frame, cand: Any, edge: EdgeFit, extras: dict[str, Any]) -> RefineResult:
        return sphere_refit(frame, cand, edge, self.physical, extras)

    def body_center(self, frame: Frame, final: RefineResult) -> BodyCenter:
        return sphere_center_of(frame, final)

    def report(self, frame: Frame, cand: Any, edge: EdgeFit) -> dict[str, Any]:
        return edge_report(frame, cand, edge)

    def iterations(self, edge: EdgeFit, final: RefineResult) -> int:
        return int(edge.circ.fit.n_steps) + (int(final.fit.n_steps) if final is not edge.circ else 0)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        if self.name != "sphere":
            return meas
        from .dark_limb import check_measurement

        return check_measurement(frame, meas)


@dataclass(frozen=True)
class Disc(Sphere):
    """A self-luminous limb-darkened disc (the Sun)."""

    physical: bool = False
    name: str = "disc"

    def refit(self, frame: Frame, cand: Any, edge: EdgeFit, extras: dict[str, Any]) -> RefineResult:
        return disc_refit(frame, edge, extras)

    def body_center(self, frame: Frame, final: RefineResult) -> BodyCenter:
        return disc_center_of(frame, final)


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


def body_strategy(frame: Frame) -> Any:
    """The strategy for the frame: ``LocateOptions.shape``, or from the hints' body (module table)."""
    shape = _shape(frame)
    if shape == BodyShape.DISC:
        if frame.opt.profile not in ("auto", "limb-darkened"):
            raise ConfigError(f"the disc strategy fits the limb-darkened disc; profile = {frame.opt.profile!s} is "
                              "not available for it")
        return Disc()
    if shape == BodyShape.ELLIPSOID:
        from .ellipsoid import Ellipsoid

        return Ellipsoid.for_frame(frame)
    if frame.opt.profile == "limb-darkened":
        raise ConfigError("profile = 'limb-darkened' is the disc strategy's (shape = 'disc' or hints body 'sun')")
    return Sphere(physical=_lunar_profile_wanted(frame))


__all__ = ["Disc", "Sphere", "body_strategy"]
