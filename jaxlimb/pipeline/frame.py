"""The first two stages of :func:`jaxlimb.pipeline.locate`: ``prepare`` (validate and bundle the inputs, Check 1
on the prior) and ``candidates`` (the front end, Checks 1-4); the typed value :class:`Frame` they pass on."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from .._programs import bound_compiled_programs
from ..errors import CheckFailed, ConfigError, ImageContentError, RadiusInconsistentError, TooManyOutliersError
from ..geometry.camera import Camera
from ..geometry.hints import Hints
from ..imaging import front_end
from ..imaging.crop import MIN_DIAMETER_PX, detect_body, nearest_fill
from ..imaging.gradient_front_end import GradientOptions
from ..imaging.io import validate_image
from ..imaging.outline import outline_front_end
from ..imaging.prior import check_prior, prior_from_hints
from ..imaging.scanline_front_end import ScanlineOptions
from ..models.small_disc import WINDOW as SMALL_WINDOW, grid_half_extent
from .options import LocateOptions
from .stages import Frame


def as_hints(hints: Any) -> Hints | None:
    """Hints from a :class:`~jaxlimb.imaging.Hints`, its dict or ``None``.

    Parameters
    ----------
    hints : Hints, dict or None
        The hints, or their JSON dict (docs/design.md).

    Returns
    -------
    Hints or None

    Raises
    ------
    ConfigError
        Any other type (or an invalid dict).
    """
    if hints is None or isinstance(hints, Hints):
        return hints
    if isinstance(hints, dict):
        return Hints.from_dict(hints)
    raise ConfigError(f"`hints` must be a jaxlimb.imaging.Hints, a dict or None, got {type(hints).__name__}")


def as_camera(camera: Any) -> Camera | None:
    """A camera from a :class:`~jaxlimb.geometry.camera.Camera`, its dict or ``None``.

    Parameters
    ----------
    camera : Camera, dict or None
        The camera, or its JSON dict (docs/design.md).

    Returns
    -------
    Camera or None

    Raises
    ------
    ConfigError
        Any other type (or an invalid dict).
    """
    if camera is None or isinstance(camera, Camera):
        return camera
    if isinstance(camera, dict):
        return Camera.from_dict(camera)
    raise ConfigError(f"`camera` must be a jaxlimb.geometry.Camera, a dict or None, got {type(camera).__name__}")


def prepare(image: Any, camera: Any, hints: Any, options: Any, mask: Any = None) -> Frame:
    """Stage 1: validate the image, camera, hints and options; Check 1 on the prior from the hints.

    A body the hints say is too small, too big or too thin is reported as such before the image
    is searched (Aerospace 2015 §3: "after internal parameter computation").

    Parameters
    ----------
    image : array_like
        2-D grey image ``[row, col]``.
    camera : Camera, dict or None
    hints : Hints, dict or None
    options : LocateOptions or None
        ``None``: the defaults.
    mask : np.ndarray of bool, optional
        Validity mask of the image's shape (``True`` = measured pixel); invalid pixels are filled
        (:func:`fill_invalid`).

    Returns
    -------
    Frame
        The validated inputs, the start time set.
    """
    bound_compiled_programs()  # a long run over frames of many sizes must not exhaust the process's memory maps
    opt = options if options is not None else LocateOptions()
    if not isinstance(opt, LocateOptions):
        raise ConfigError(f"`options` must be a LocateOptions, got {type(opt).__name__}")
    t0 = time.perf_counter()
    img = validate_image(image, reject_constant=False)
    cam = as_camera(camera)
    hin = as_hints(hints)
    if cam is not None and (cam.rows, cam.cols) != img.shape:
        raise ConfigError(f"camera size {cam.rows}x{cam.cols} does not match the image size {img.shape[0]}x{img.shape[1]}")
    if mask is not None and np.shape(mask) != img.shape:
        raise ConfigError(f"mask shape {np.shape(mask)} does not match the image size {img.shape}")
    mask = None if mask is None else np.asarray(mask, dtype=bool)
    if mask is not None and not mask.all():
        img = fill_invalid(img, mask)
    frame = Frame(img, cam, hin, opt, t0, mask=mask)
    if hin is not None and not arc_only(frame) and not small_expected(frame):  # (its arc / the whole blob is measured)
        fe = frame.front_end_options()
        popt = None if fe is None else fe.prior
        pri0 = prior_from_hints(hin, cam, options=popt, check=True)
        if pri0 is not None and cam is None:
            check_prior(pri0, img.shape, popt)
    return frame


def fill_invalid(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A copy of ``img`` whose invalid pixels hold the median of the valid ones (the convention of
    :func:`jaxlimb.imaging.formats.read_frame`): whatever a caller left there (zeros, saturated fill)
    shows no step to a stage that reads the image without the mask (body detection, the prior).

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image; its dtype is kept (integers get the rounded median).
    mask : np.ndarray of bool (rows, cols)
        ``True`` = valid pixel.

    Returns
    -------
    np.ndarray (rows, cols)

    Raises
    ------
    ImageContentError
        No valid pixel.
    """
    if not mask.any():
        raise ImageContentError("the validity mask marks every pixel invalid: nothing to measure")
    out = np.array(img)  # (the dtype is kept: the saturation level of integer frames depends on it)
    med = float(np.median(out[mask]))
    out[~mask] = round(med) if np.issubdtype(out.dtype, np.integer) else med
    return out


def limb_predicted(frame: Frame) -> bool:
    """The hints place the limb (SPICE-like prediction: expected centre, range prior, radii, pinhole camera).

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    bool
    """
    cam, h = frame.cam, frame.hints
    return (cam is not None and not cam.has_distortion and h is not None and h.expected_center_rc is not None
            and h.range_prior_km is not None and h.radius_km() is not None)


def arc_only(frame: Frame) -> bool:
    """Camera (pinhole), range and radius known, and the expected disc larger than the frame's half-diagonal.

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    bool
        ``f_px tan(asin(R / range))`` exceeds half the frame diagonal.
    """
    cam, h = frame.cam, frame.hints
    if cam is None or cam.has_distortion or h is None or h.radius_km() is None or h.range_prior_km is None:
        return False
    rkm, rng = h.radius_km(), h.range_prior_km
    return rng > rkm and cam.focal_px * math.tan(math.asin(rkm / rng)) > 0.5 * math.hypot(*frame.img.shape)


#: Expected apparent radius (px) below which a body is measured as a whole (:mod:`jaxlimb.pipeline.small`), not on its
#: limb: below it the limb strategy refuses the body (Check 1, a 10 px diameter) or, by a range prior a few per cent
#: off, may; from 7 px up the limb fit is as accurate and its covariance more faithful (``benchmarks/small_bodies.py``).
SMALL_RADIUS_MAX_PX = 6.0

#: Fractional 1-sigma of the expected radius when the hints give none: the few-pixel fit's consider term
#: (:mod:`jaxlimb.pipeline.small`) and the predicted limb's radius band (Check 4's band is 3 of it,
#: :mod:`jaxlimb.pipeline.sphere.predicted`).
DEFAULT_RADIUS_UNCERTAINTY = 0.05


def expected_radius_px(frame: Frame) -> float | None:
    """The apparent radius (px) the hints give: ``expected_radius_px``, else from the camera, the range and the radius
    (Aerospace 2015 Eq. 1); ``None`` when they fix none.

    Parameters
    ----------
    frame : Frame
        Its hints (and camera) give the radius.

    Returns
    -------
    float or None
        Apparent radius (px).
    """
    cam, h = frame.cam, frame.hints
    if h is None:
        return None
    if h.expected_radius_px is not None:
        return float(h.expected_radius_px)
    rkm, rng = h.radius_km(), h.range_prior_km
    if cam is None or rkm is None or rng is None or rng <= rkm:
        return None
    return float(cam.focal_px * math.tan(math.asin(rkm / rng)))


def small_expected(frame: Frame) -> bool:
    """The hints put the body below :data:`SMALL_RADIUS_MAX_PX` of apparent radius and give the Sun direction (the
    few-pixel strategy's phase); without it such a body is refused by Check 1, as too small for a limb.

    Parameters
    ----------
    frame : Frame
        Its hints give the expected radius and the Sun direction.

    Returns
    -------
    bool
        ``True`` when the few-pixel strategy applies.
    """
    pr = expected_radius_px(frame)
    return pr is not None and pr < SMALL_RADIUS_MAX_PX and frame.sun_known


def small_possible(frame: Frame) -> bool:
    """The few-pixel model can hold the body the hints expect: the Sun direction known and the disc's radiance grid
    (:func:`~jaxlimb.models.small_disc.grid_half_extent`) inside the model's window of pixels.

    Parameters
    ----------
    frame : Frame
        Its hints (and camera) give the expected radius and the Sun direction.

    Returns
    -------
    bool
        ``True`` when :mod:`jaxlimb.pipeline.small` can measure the body as a whole.
    """
    pr = expected_radius_px(frame)
    return pr is not None and frame.sun_known and grid_half_extent(pr) <= 0.5 * SMALL_WINDOW


def frame_mask(frame: Frame) -> np.ndarray | None:
    """The validity mask of ``frame.img`` (``None`` when all valid or when a strategy resampled the frame:
    the observed mask no longer fits its grid).

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    np.ndarray of bool (rows, cols) or None
    """
    return frame.mask if frame.observed_cam is None else None


#: Above this phase (deg, from the hints) the front ends keep Eq. (10)'s region (:attr:`DetectOptions.dark_surface` off):
#: the variegated-body region is for the nearly full disc (the Earth from deep space), where a Lambert limb fades
#: to zero all round; a gibbous cloudy Earth's limb is traced against the sky downstream
#: (:mod:`jaxlimb.pipeline.ellipsoid.trace`), whose starts were measured on Eq. (10)'s circles.
DARK_SURFACE_MAX_PHASE_DEG = 30.0


def _front_end_options(frame: Frame, name: str) -> Any:
    """The options of front end ``name`` (``None``: defaults), with the variegated-body region off above
    :data:`DARK_SURFACE_MAX_PHASE_DEG` of phase."""
    opt = frame.front_end_options(name) or (GradientOptions() if name == "gradient" else ScanlineOptions())
    if not (frame.sun_known and opt.detect.dark_surface):
        return opt
    center = (0.5 * (frame.img.shape[0] - 1), 0.5 * (frame.img.shape[1] - 1))  # the phase hardly varies over a frame
    if math.degrees(frame.phase(center)) <= DARK_SURFACE_MAX_PHASE_DEG:
        return opt
    return replace(opt, detect=replace(opt.detect, dark_surface=False))


def _variegated(frame: Frame, name: str, mask) -> bool:  # type: ignore[no-untyped-def]
    """Whether the detected region is a variegated body's (:attr:`~jaxlimb.imaging.crop.BodyRegion.dark_surface`):
    only then is the other front end tried for a body whose limb the front end's circle decides.  On other frames a
    second front end's circle is no better founded than the first's refusal: the EUV Sun of ``aia_171_level1.fits``,
    refused by the gradient front end, was answered ``ok`` 1.9 px off with a 0.25 px sigma by the scan lines and a
    limb-darkened disc (a model of another limb).  A disc's profile fit on the full annulus decides its limb (the
    circle only starts it): :func:`candidates` with ``any_region``."""

    detect = _front_end_options(frame, name).detect
    try:
        return bool(detect_body(nearest_fill(np.asarray(frame.img, dtype=float), mask), detect).dark_surface)
    except CheckFailed:
        return False


def candidates(frame: Frame, any_region: bool = False) -> Any:
    """Stage 2: the front end's limb candidates, circle and lit direction (Checks 1-4); the other front end when the
    chosen one finds no limb (:attr:`LocateOptions.front_end_fallback`) on a variegated body or, with
    ``any_region``, on any.

    Parameters
    ----------
    frame : Frame
    any_region : bool
        Try the other front end whatever the region (a strategy whose profile fit decides the limb).

    Returns
    -------
    LimbCandidates
        The front end's answer (:func:`jaxlimb.imaging.front_end`): limb points, initial circle, lit
        direction, the detected region in ``info``.
    """
    mask = frame_mask(frame)
    name = str(frame.opt.front_end)
    try:
        cand = front_end(name, frame.img, None, hints=frame.hints, camera=frame.cam,
                         options=_front_end_options(frame, name), mask=mask)
    except (TooManyOutliersError, RadiusInconsistentError) as first:
        if not (frame.opt.front_end_fallback and (any_region or _variegated(frame, name, mask))):
            raise
        try:
            cand = other_candidates(frame)
        except CheckFailed as second:
            raise type(first)(f"{first}; the {other_front_end(frame)} front end too: {second}") from second
    frame.mark("front_end")
    return cand


def outline_candidates(frame: Frame) -> Any:
    """Stage 2 of a self-luminous disc: the outline of its bright region (:func:`~jaxlimb.imaging.outline.
    outline_front_end`: a star has no lit side, and its limb all round is that outline); :func:`candidates` with
    ``any_region`` when the outline holds too few points of the disc's edge.

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    LimbCandidates
        The outline's circle and points (``front_end="outline"``), or the chosen front end's answer.
    """
    try:
        cand = outline_front_end(frame.img, frame_mask(frame))
    except TooManyOutliersError:
        return candidates(frame, any_region=True)
    frame.mark("front_end")
    return cand


def other_front_end(frame: Frame) -> str:
    """The name of the front end not chosen in ``frame.opt``.

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    str
        ``"gradient"`` or ``"scanline"``.
    """
    return "scanline" if str(frame.opt.front_end) == "gradient" else "gradient"


def other_candidates(frame: Frame) -> Any:
    """The limb candidates of the front end not chosen (:func:`other_front_end`), for the fallbacks of
    :func:`candidates` and :func:`jaxlimb.pipeline.locate.locate`.

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    LimbCandidates
        As :func:`candidates`.
    """
    other = other_front_end(frame)
    return front_end(other, frame.img, None, hints=frame.hints, camera=frame.cam,
                     options=_front_end_options(frame, other), mask=frame_mask(frame))


def min_diameter_px(frame: Frame) -> float:
    """Check 1's smallest diameter: the gradient front end's prior setting, else
    :data:`~jaxlimb.imaging.crop.MIN_DIAMETER_PX` (10 px).

    Parameters
    ----------
    frame : Frame

    Returns
    -------
    float
        Diameter (px).
    """
    if frame.opt.gradient is not None and frame.opt.front_end == "gradient":
        return float(frame.opt.gradient.prior.min_diameter_px)  # type: ignore[attr-defined]
    return MIN_DIAMETER_PX


def arc_angles(coords: np.ndarray, center_rc) -> np.ndarray:
    """Polar angles (rad) of pixels about a centre.

    Parameters
    ----------
    coords : np.ndarray (n, 2)
        Pixels ``(row, col)``.
    center_rc : (float, float)
        Centre ``(row, col)``.

    Returns
    -------
    np.ndarray (n,)
        ``atan2(d_row, d_col)`` in ``(-pi, pi]``.
    """
    return np.arctan2(coords[:, 0] - float(center_rc[0]), coords[:, 1] - float(center_rc[1]))


__all__ = ["DEFAULT_RADIUS_UNCERTAINTY", "SMALL_RADIUS_MAX_PX", "arc_angles", "as_camera", "as_hints", "candidates",
           "expected_radius_px", "frame_mask", "limb_predicted", "min_diameter_px", "other_candidates", "other_front_end",
           "prepare", "small_expected", "small_possible"]
