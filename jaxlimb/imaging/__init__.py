"""Image input/validation and the two front ends (gradient; scan line), the §3 prior, crop detection.

Public API (all re-exported here):

* input: :func:`load_image`, :func:`validate_image`, :class:`ImageInfo`,
  :class:`ColourImageWarning`, :func:`read_jp2_header`;
  SDO truth: :func:`sun_truth_from_header`, :class:`SunTruth`, :func:`hmi_512_truth`;
* prior (Aerospace 2015 §3): :class:`Hints`, :class:`Prior`, :class:`PriorOptions`,
  :func:`prior_from_hints`, :func:`prior_from_image`, :func:`illumination_parameter`,
  :func:`derived_settings`, :func:`ransac_tests`, :func:`check_prior`, :func:`sun_direction_image`;
* detection: :func:`detect_body`, :class:`BodyRegion`, :class:`DetectOptions`,
  :func:`detect_cropping`, :class:`CropInfo`;
* gradient front end (§4-5): :func:`gradient_front_end`, :class:`GradientOptions`,
  :func:`richardson_gradient`, :func:`box_filter`;
* scan-line front end (illuminated-ellipsoid §IV-A, §VI): :func:`scanline_front_end`,
  :class:`ScanlineOptions`, :func:`inertia_axes`;
* the common result: :class:`LimbCandidates`; :func:`front_end` dispatches by name.
"""

from __future__ import annotations

from ..errors import ConfigError

from .boxfilter import box_filter as box_filter
from .candidates import LimbCandidates as LimbCandidates, lit_arc as lit_arc
from .crop import (
    BodyRegion as BodyRegion,
    CropInfo as CropInfo,
    DetectOptions as DetectOptions,
    detect_body as detect_body,
    detect_cropping as detect_cropping,
    estimate_noise as estimate_noise,
)
from .gradient import (
    richardson_gradient as richardson_gradient,
    strongest_pixels as strongest_pixels,
    subpixel_refine as subpixel_refine,
)
from .gradient_front_end import GradientOptions as GradientOptions, gradient_front_end as gradient_front_end
from .io import (
    ColourImageWarning as ColourImageWarning,
    ImageInfo as ImageInfo,
    load_image as load_image,
    read_jp2_header as read_jp2_header,
    validate_image as validate_image,
)
from ..geometry.hints import Hints as Hints
from .prior import (
    Prior as Prior,
    PriorOptions as PriorOptions,
    Settings as Settings,
    check_prior as check_prior,
    derived_settings as derived_settings,
    illumination_parameter as illumination_parameter,
    prior_from_hints as prior_from_hints,
    prior_from_image as prior_from_image,
    ransac_tests as ransac_tests,
    sun_direction_image as sun_direction_image,
)
from .scanline import inertia_axes as inertia_axes, scan_transitions as scan_transitions
from .scanline_front_end import ScanlineOptions as ScanlineOptions, scanline_front_end as scanline_front_end
from .sdo import SunTruth as SunTruth, hmi_512_truth as hmi_512_truth, sun_truth_from_header as sun_truth_from_header


def front_end(name: str, image, prior=None, *, hints=None, camera=None, options=None, mask=None) -> LimbCandidates:
    """Run the front end called ``name`` (``"gradient"`` or ``"scanline"``).

    ``hints`` may be a :class:`Hints` or the hints JSON dict; ``options`` must be the
    matching :class:`GradientOptions` / :class:`ScanlineOptions` (or ``None``); ``mask`` (``True``
    = valid) is respected by both: masked pixels are neither limb nor background.

    Raises
    ------
    jaxlimb.errors.ConfigError
        Unknown name, options of the other front end, or bad hints.
    """
    kinds = {"gradient": (gradient_front_end, GradientOptions), "scanline": (scanline_front_end, ScanlineOptions)}
    if name not in kinds:
        raise ConfigError(f"front_end must be 'gradient' or 'scanline', got {name!r}")
    fn, opt_type = kinds[name]
    if options is not None and not isinstance(options, opt_type):
        raise ConfigError(f"options for the {name} front end must be {opt_type.__name__}, got {type(options).__name__}")
    if hints is not None and not isinstance(hints, Hints):
        hints = Hints.from_dict(hints)
    return fn(image, prior, hints=hints, camera=camera, options=options, mask=mask)


__all__ = [
    "BodyRegion",
    "ColourImageWarning",
    "CropInfo",
    "DetectOptions",
    "GradientOptions",
    "Hints",
    "ImageInfo",
    "LimbCandidates",
    "Prior",
    "PriorOptions",
    "ScanlineOptions",
    "Settings",
    "SunTruth",
    "box_filter",
    "check_prior",
    "derived_settings",
    "detect_body",
    "detect_cropping",
    "estimate_noise",
    "front_end",
    "gradient_front_end",
    "hmi_512_truth",
    "illumination_parameter",
    "inertia_axes",
    "lit_arc",
    "load_image",
    "prior_from_hints",
    "prior_from_image",
    "ransac_tests",
    "read_jp2_header",
    "richardson_gradient",
    "scan_transitions",
    "scanline_front_end",
    "strongest_pixels",
    "subpixel_refine",
    "sun_direction_image",
    "sun_truth_from_header",
    "validate_image",
]
