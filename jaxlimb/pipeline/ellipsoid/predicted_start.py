"""The ellipsoid's start from a predicted limb: a spheroid whose limb the hints place (SPICE: camera, range, radii,
orientation, expected centre), its candidates from the predicted-limb front end (:mod:`jaxlimb.imaging.predicted`).

Why: the shared front end looks for one circle, and on a giant planet it finds none (its banded, limb-darkened disc
sits in a halo of scattered light: the Cassini Jupiter frame of ``benchmarks/real_frames.py``); the fallback start
(:func:`~jaxlimb.pipeline.ellipsoid.start.blob_candidates`) puts the disc's sunward extreme in that halo, tens of
pixels out.  The edges found along the predicted limb's normals, fitted with the predicted shape (axis ratio and
orientation: the radii and the pole, which a pointing error does not change), give the centre and the size the
ellipse's edge fit starts from, as they do for the predicted-limb sphere
(:class:`~jaxlimb.pipeline.sphere.predicted.PredictedLimbSphere`).
"""

from __future__ import annotations

import math
from typing import Any

from ...errors import TooManyOutliersError
from ...imaging.candidates import LimbCandidates
from ...imaging.prior import sun_direction_image
from ..frame import limb_predicted
from ..sphere.predicted import predicted_candidates
from ..stages import Frame
from .model import EllipsoidModel
from .start import ellipsoid_candidates


def predicted_start(frame: Frame) -> LimbCandidates | None:
    """The predicted-limb front end's answer as the ellipsoid's candidates.

    Parameters
    ----------
    frame : Frame
        The prepared frame; its hints predict the limb (:func:`~jaxlimb.pipeline.frame.limb_predicted`).

    Returns
    -------
    LimbCandidates or None
        The edge points the shape fit kept, the circle of the fitted ellipse's mean radius ``sqrt(a b)`` at its
        centre and the Sun's image direction as the lit side (the whole limb without it); ``None`` when too few
        edges lie along the predicted limb.
    """
    try:
        pc = predicted_candidates(frame)
    except TooManyOutliersError:
        return None
    shape, h = pc.shape, frame.hints
    sd = None if h is None or h.sun_dir_camera is None else sun_direction_image(h.sun_dir_camera, frame.cam,
                                                                               shape.center_rc)
    return LimbCandidates(pc.points_rc[pc.used], (float(shape.center_rc[0]), float(shape.center_rc[1])),
                          float(shape.a * math.sqrt(shape.rho)), math.nan, None if sd is None else tuple(sd),
                          math.pi / 2 if sd is not None else math.pi, "predicted",
                          {"predicted_center_rc": list(pc.predicted.center_rc), "predicted_a_px": pc.predicted.a})


def spheroid_candidates(body: EllipsoidModel, frame: Frame) -> Any:
    """Stage "candidates" of the ellipsoid: the predicted limb's (:func:`predicted_start`) when the hints predict
    the limb and the body is not the Earth (whose frames keep the shared front end and its cloud-edge fallbacks,
    :func:`~jaxlimb.pipeline.ellipsoid.start.ellipsoid_candidates`), else, or when it finds too few edges, the
    shared front end's.

    Parameters
    ----------
    body : EllipsoidModel
        The body.
    frame : Frame
        The prepared frame.

    Returns
    -------
    LimbCandidates
        The start of the ellipse's trace and edge fit.
    """
    if limb_predicted(frame) and frame.hints is not None and frame.hints.body != "earth":
        cand = predicted_start(frame)
        if cand is not None:
            return cand
    return ellipsoid_candidates(body, frame)


__all__ = ["predicted_start", "spheroid_candidates"]
