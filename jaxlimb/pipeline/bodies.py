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
``SmallBody``            a body of a few pixels (expected     the whole blob: the blurred lit disc at the phase; its
                         radius below 6 px, Sun direction     centre of brightness corrected for the phase when that
                         known)                               fit fails
=======================  ===================================  ==========================================================
"""

from __future__ import annotations

from ..errors import ConfigError
from .ellipsoid.body import Ellipsoid
from .frame import arc_only, limb_predicted, small_expected
from .options import BodyShape
from .small.body import SmallBody
from .sphere.body import Disc, Sphere
from .sphere.predicted import PredictedLimbSphere
from .stages import Body, Frame


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
    if small_expected(frame):
        return BodyShape.SMALL
    return BodyShape.SPHERE


def body_strategy(frame: Frame) -> Body:
    """The strategy for the frame: ``LocateOptions.shape``, or from the hints' body (module table); a sphere whose
    limb the hints predict (camera, range, radii, expected centre: SPICE) is measured on its whole limb, one whose
    expected disc exceeds the frame on its visible arc.

    Parameters
    ----------
    frame : Frame
        The prepared inputs (options, hints, camera, image size).

    Returns
    -------
    Body
        ``Disc``, ``Ellipsoid``, ``SmallBody``, ``PredictedLimbSphere`` or ``Sphere`` (with the lunar-Lambert profile when
        ``profile="auto"`` and the Sun direction is known).

    Raises
    ------
    ConfigError
        A profile the chosen strategy does not fit (``limb-darkened`` off the disc, another profile on it).
    """
    shape = _shape(frame)
    if shape == BodyShape.DISC:
        if frame.opt.profile not in ("auto", "limb-darkened"):
            raise ConfigError(f"the disc strategy fits the limb-darkened disc; profile = {frame.opt.profile!s} is "
                              "not available for it")
        return Disc()
    if shape == BodyShape.ELLIPSOID:
        return Ellipsoid.for_frame(frame)
    if shape == BodyShape.SMALL:
        return SmallBody()
    if frame.opt.profile == "limb-darkened":
        raise ConfigError("profile = 'limb-darkened' is the disc strategy's (shape = 'disc' or hints body 'sun')")
    if limb_predicted(frame) or arc_only(frame):
        return PredictedLimbSphere(arc=not limb_predicted(frame))
    return Sphere(physical=_lunar_profile_wanted(frame))


__all__ = ["body_strategy"]
