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
``Ellipsoid``            Earth; any spheroid whose polar      band about the predicted limb ellipse (rho, theta
                         and equatorial limbs differ by more  from the limb cone); ESF with interior ramp;
                         than the limb model's edge error     lunar-Lambert profile (``L`` fitted: the limb's
                         at its apparent size (Jupiter,       darkening); Earth offset and range iteration
                         Saturn, Mars)                        (Mortari et al. §IV, Fig. 2); started from the predicted
                                                              limb when the hints predict it (not the Earth)
``Disc``                 the Sun                              its region's outline; full annulus; CSF and the
                                                              limb-darkened disc, or (brightest at its limb: the
                                                              EUV) the corona over an opaque disc; its centre
``SmallBody``            a body of a few pixels (expected     the whole blob: the blurred lit disc at the phase; its
                         radius below 6 px, Sun direction     centre of brightness corrected for the phase when that
                         known)                               fit fails
=======================  ===================================  ==========================================================

A spheroid (``a = b != c``) is measured as one when the largest difference of its limb from a circle, the apparent
``(a - c)`` in pixels (:func:`spheroid_departure_px`: its pole in the image plane, at the range prior's or the expected
radius's scale, else at the smallest disc Check 1 measures), exceeds the edge-position error the round strategies
claim for their limb model (:data:`~jaxlimb.pipeline.sphere.predicted.EDGE_MODEL_SIGMA_PX`): below it a circle fits
the limb as well as the model does.  A triaxial body (``a != b``: Enceladus, Mimas) stays round, its predicted limb
ellipse held when SPICE predicts it.
"""

from __future__ import annotations

import math

from ..errors import ConfigError
from ..geometry.bodies import BODY_TABLE
from .ellipsoid.body import Ellipsoid
from .frame import arc_only, limb_predicted, min_diameter_px, small_expected
from .options import BodyShape
from .small.body import SmallBody
from .sphere.body import Disc, Sphere
from .sphere.predicted import EDGE_MODEL_SIGMA_PX, PredictedLimbSphere
from .stages import Body, Frame


def _lunar_profile_wanted(frame: Frame) -> bool:
    """``profile="auto"``: the physical profile for a sunlit body whose Sun direction is known (circle model,
    ``k`` estimated; the papers' fixed-``k`` setting, Table 1, is a sigmoid experiment); else as asked."""
    opt, h = frame.opt, frame.hints
    if opt.profile != "auto":
        return opt.profile in ("lunar-lambert", "albedo-field")
    return opt.model == "circle" and opt.estimate_k and frame.sun_known and h is not None and h.body != "sun"


def spheroid_departure_px(frame: Frame) -> float:
    """The apparent difference ``(a - c)`` (px) of the equatorial and polar limb radii of the hints' spheroid, its pole
    in the image plane (the largest departure of its limb from a circle): ``f tan(asin(R / D))`` at the range prior
    ``D``, else the expected radius times ``1 - c / a``, else the smallest disc Check 1 measures
    (:func:`~jaxlimb.pipeline.frame.min_diameter_px`) times it.

    Parameters
    ----------
    frame : Frame
        The validated inputs (hints radii or body, range prior or expected radius, camera).

    Returns
    -------
    float
        The departure (px); ``0`` for a sphere, a triaxial body (``a != b``), a body without known radii or a frame
        without a camera (the ellipsoid measures the range: it needs one).
    """
    h, cam = frame.hints, frame.cam
    if h is None or cam is None:
        return 0.0
    radii = h.body_radii_km
    if radii is None and h.body in BODY_TABLE:
        radii = BODY_TABLE[h.body].radii_km
    if radii is None:
        return 0.0
    a, b, c = (float(v) for v in radii)
    if abs(a - b) > 1e-9 * a or a == c:
        return 0.0
    D = h.range_prior_km
    if D is not None and D > a:
        return abs(cam.focal_px * (math.tan(math.asin(a / D)) - math.tan(math.asin(c / D))))
    size = h.expected_radius_px if h.expected_radius_px else 0.5 * min_diameter_px(frame)
    return size * abs(1.0 - c / a)


def _shape(frame: Frame) -> BodyShape:
    opt, h = frame.opt, frame.hints
    if opt.shape != BodyShape.AUTO:
        return opt.shape
    if opt.profile in ("limb-darkened", "corona") or (opt.profile == "auto" and opt.model == "circle" and opt.estimate_k
                                          and h is not None and h.body == "sun"):
        return BodyShape.DISC
    if h is not None and h.body == "earth":
        return BodyShape.ELLIPSOID
    if small_expected(frame):
        return BodyShape.SMALL
    if (opt.estimate_k and opt.profile != "limb-darkened" and not arc_only(frame)
            and spheroid_departure_px(frame) > EDGE_MODEL_SIGMA_PX):
        return BodyShape.ELLIPSOID
    return BodyShape.SPHERE


def body_strategy(frame: Frame) -> Body:
    """The strategy for the frame: ``LocateOptions.shape``, or from the hints' body and radii (module table); a sphere whose
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
        if frame.opt.profile not in ("auto", "limb-darkened", "corona"):
            raise ConfigError(f"the disc strategy fits the limb-darkened disc or the EUV corona; profile = "
                              f"{frame.opt.profile!s} is not available for it")
        return Disc()
    if shape == BodyShape.ELLIPSOID:
        return Ellipsoid.for_frame(frame)
    if shape == BodyShape.SMALL:
        return SmallBody()
    if frame.opt.profile in ("limb-darkened", "corona"):
        raise ConfigError(f"profile = {frame.opt.profile!r} is the disc strategy's (shape = 'disc' or hints body 'sun')")
    if limb_predicted(frame) or arc_only(frame):
        return PredictedLimbSphere(arc=not limb_predicted(frame))
    return Sphere(physical=_lunar_profile_wanted(frame))


__all__ = ["body_strategy", "spheroid_departure_px"]
