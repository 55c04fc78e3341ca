r"""``locate``: image -> image of the body centre, apparent radius / limb ellipse, line of sight and range.

One pipeline for every body, a short composition of the stages of :mod:`jaxlimb.pipeline.stages` (prepare,
candidates, limb pixels, edge fit, profile refit, body-centre mapping, covariance, checks, result: the Aerospace 2015
paper's flow with Mortari et al.'s ellipsoid), typed values between them; the body strategy
(:func:`jaxlimb.pipeline.bodies.body_strategy`) supplies what differs, and ``locate`` never asks which one it has.

A camera with lens distortion: the round bodies fit ideal (undistorted) pixel coordinates and distort
the body-centre image back; the ellipsoid resamples the frame onto the ideal grid
(:mod:`jaxlimb.pipeline.ellipsoid`) and maps the centre and its covariance back.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import CheckFailed
from ..geometry.camera import Camera
from ..geometry.hints import Hints
from .bodies import body_strategy
from .frame import other_candidates, prepare
from .options import LocateOptions
from .report import covariance, levels, measurement
from .result import LimbMeasurement
from .stages import Body, Frame
from .sphere.edge import InitialCircleOffError


def locate(
    image: Any,
    camera: Camera | dict | None = None,
    hints: Hints | dict | None = None,
    options: LocateOptions | None = None,
    *,
    mask: np.ndarray | None = None,
) -> LimbMeasurement:
    """Locate the body in ``image``: centre of the body's image, radius, LOS and range (module docstring).

    Parameters
    ----------
    image : array_like (rows, cols)
        Grey image ``[row, col]`` (any numeric dtype; colour is converted with a warning).
    camera : Camera, dict or None
        Enables the body-centre correction, the line of sight and the range (the ellipsoid strategy needs it).
    hints : Hints, dict or None
        The prior (docs/design.md): body (``earth``: ellipsoid strategy, ``sun``: disc), radii, range, Sun direction,
        attitude ...  Hints predicting a sphere's limb (expected centre, range, radii: SPICE) have the whole limb,
        lit and dark, measured (:mod:`jaxlimb.pipeline.sphere.predicted`), or the visible arc of a too-large disc.
    options : LocateOptions, optional
    mask : np.ndarray of bool (rows, cols), optional
        Validity mask (``True`` = measured pixel); masked pixels are neither limb nor background.

    Returns
    -------
    LimbMeasurement
        ``center_rc`` the image of the **body centre** (with a camera) or the circle centre (without); ``covariance``
        one matrix over the mapped quantities and the other fit parameters; ``extras`` the checks' numbers, timings.

    Raises
    ------
    ImageContentError, ConfigError, GeometryError
        Unusable image / camera / hints / options (CLI exit 2).
    CheckFailed
        A check failed (CLI exit 3; :mod:`jaxlimb.pipeline.checks`): no body, too small/big/thin, no convergence ...

    Examples
    --------
    >>> import jax, numpy as np; jax.config.update("jax_enable_x64", True)
    >>> rr, cc = np.mgrid[:200, :240]
    >>> image = 20 + 180 / (1 + np.exp(1.5 * (np.hypot(rr - 95.3, cc - 130.6) - 60.0)))  # a disc, no noise
    >>> m = locate(image)
    >>> m.to_json()["status"], [round(v, 1) for v in m.center_rc], round(m.radius_px, 1)
    ('ok', [95.3, 130.6], 60.0)
    """
    frame = prepare(image, camera, hints, options, mask)
    body = body_strategy(frame)
    try:
        return _measure_body(frame, body)
    except CheckFailed as e:
        other = body.instead(frame, e)
        if other is None:
            raise
        try:
            m = _measure_body(frame, other)
        except CheckFailed:
            raise e from None
        m.extras["strategy_refused"] = {"check": e.check, "message": str(e)}  # the first strategy's refusal
        return m


def _measure_body(frame: Frame, body: Body) -> LimbMeasurement:
    """The body strategy's stages on the prepared frame: prepare, candidates, then :func:`_measure_or_other_front_end`
    (a refusal on a frame whose sky outshines the shadowed limb says so)."""
    frame = body.prepare(frame)
    cand = body.candidates(frame)
    try:
        return _measure_or_other_front_end(frame, body, cand)
    except CheckFailed as e:
        region = cand.info.get("region")
        if region is None or not region.bright_sky:
            raise
        raise type(e)(  # the same check, with what makes this frame hard
            f"{e} [the sky ({region.background:.4g} DN at the frame's border) is brighter than the body's shadowed "
            "limb: only the lit arc is a lit limb, and the lit-limb model alone could not measure this frame]"
        ) from None


def _measure_or_other_front_end(frame: Frame, body: Body, cand: Any) -> LimbMeasurement:
    """:func:`_measure`, and on :class:`~jaxlimb.pipeline.sphere.edge.InitialCircleOffError` (the Sun-facing annulus in the
    frame but few of its bins with a lit edge: the front end's circle off the limb) :func:`_measure` on the other
    front end's candidates (``front_end_fallback``); the first failure stands when that one fails too."""
    try:
        return _measure(frame, body, cand)
    except InitialCircleOffError as first:
        if not frame.opt.front_end_fallback:
            raise
        try:
            return _measure(frame, body, other_candidates(frame))
        except CheckFailed:
            raise first from None


def _measure(frame: Frame, body: Body, cand: Any) -> LimbMeasurement:
    """Stages 3-9 of :func:`locate` (:mod:`jaxlimb.pipeline.stages`) on the front end's candidates."""
    pixels = body.limb_pixels(frame, cand)
    edge = body.edge_fit(frame, cand, pixels)
    extras = body.report(frame, cand, edge)
    final = body.refit(frame, cand, edge, extras)
    frame.mark("profile")
    geo = body.body_center(frame, edge, final)
    cov = covariance(final, geo)
    frame.mark("body_center")
    lev = levels(final)
    body.check(frame, lev, cov)
    return body.finish(frame, measurement(frame, cand, final, geo, cov, lev, extras, body.iterations(edge, final)))


__all__ = ["locate"]
