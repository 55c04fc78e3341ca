"""Settings of :func:`jaxlimb.pipeline.locate`: :class:`LocateOptions` and the ellipsoid strategy's
:class:`EllipsoidOptions` nested in it (the front ends' own, :class:`~jaxlimb.imaging.GradientOptions` and
:class:`~jaxlimb.imaging.ScanlineOptions`, live beside them).  A number no benchmark or user varies is a constant
next to its use, not a setting."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from .._validate import NON_NEGATIVE, POSITIVE, number
from ..errors import ConfigError
from ..fitting import SOLVERS
from ..imaging import GradientOptions, ScanlineOptions


class _Choice(str, Enum):
    """A setting with named values; compares equal to its string (``FrontEnd.GRADIENT == "gradient"``)."""

    def __str__(self) -> str:
        return str(self.value)

    @classmethod
    def parse(cls, name: str, v: object) -> "_Choice":
        try:
            return cls(v)
        except ValueError:
            raise ConfigError(f"LocateOptions.{name} must be one of {[m.value for m in cls]}, got {v!r}") from None


class FrontEnd(_Choice):
    """The limb-candidate front end (:func:`jaxlimb.imaging.front_end`)."""

    GRADIENT = "gradient"
    SCANLINE = "scanline"


class LimbModelKind(_Choice):
    """The limb's shape in the edge fit: a circle (a sphere's limb, corrected to its ellipse with a camera)
    or a free ellipse."""

    CIRCLE = "circle"
    ELLIPSE = "ellipse"


class Profile(_Choice):
    """The edge model of the profile-refit stage."""

    AUTO = "auto"
    SIGMOID = "sigmoid"
    LUNAR_LAMBERT = "lunar-lambert"
    ALBEDO_FIELD = "albedo-field"
    LIMB_DARKENED = "limb-darkened"
    CORONA = "corona"


class BodyShape(_Choice):
    """The body strategy of :func:`~jaxlimb.pipeline.locate`: ``auto`` (the Sun: ``disc``; the Earth, and a spheroid
    whose flattening the frame resolves: ``ellipsoid``; a body of a few pixels: ``small``; any other body:
    ``sphere``; :func:`~jaxlimb.pipeline.bodies.body_strategy`), or one of them."""

    AUTO = "auto"
    SPHERE = "sphere"
    ELLIPSOID = "ellipsoid"
    DISC = "disc"
    SMALL = "small"


FRONT_ENDS = tuple(m.value for m in FrontEnd)
LIMB_MODELS = tuple(m.value for m in LimbModelKind)
PROFILES = tuple(m.value for m in Profile)


def _pos(name: str, v: object, *, allow_zero: bool = False, allow_none: bool = False) -> None:
    if v is None and allow_none:
        return
    number(v, f"LocateOptions.{name}", NON_NEGATIVE if allow_zero else POSITIVE)


@dataclass(frozen=True)
class EllipsoidOptions:
    """Settings of the ellipsoid strategy (:mod:`jaxlimb.pipeline.ellipsoid`; ``LocateOptions.ellipsoid``).

    Attributes
    ----------
    band_px
        Half-width (px) of the pixel band about the current ellipse used in the edge fit.
    arc_margin_deg
        Degrees removed from each end of the lit arc (the horns, where the limb meets the terminator and the edge
        fades).
    interior_ramp
        Fit :data:`~jaxlimb.models.ELLIPSE_RAMP` (the ESF plus a brightness ramp inside the limb, default) instead of
        the paper's flat-topped ESF (``False``; no profile refit then); see :func:`~jaxlimb.models.ellipse_ramp_intensity`.
    center_floor_px
        Smallest 1-sigma (px) of the ellipse centre in any direction: the limb model's specification error, which no
        residual shows (``benchmarks/families.py``: uniform-albedo Earths 0.005-0.025 px off for noise sigmas of
        0.001-0.007 px).  ``0`` keeps the noise and model-error terms alone.
    sun_declination_max_deg
        Attitude unknown, Sun direction known: the largest angle (deg) between the Sun and the body's equator (the
        Earth: its obliquity, 23.44).  The centre is then marginalised over the poles that bound allows
        (:mod:`jaxlimb.pipeline.ellipsoid.pole_prior`).  ``None`` (default): no bound (the cone axis and the unsigned
        offset as a uniform error).  Not for scenes whose Sun is placed freely (a renderer's).
    unresolved_glow
        ``(g_max, H_lo_km, H_hi_km)``: the glow above the measured edge that the covariance carries when the profile
        fit has none (:func:`~jaxlimb.pipeline.ellipsoid.profile.with_unresolved_glow`): its brightness uniform up to
        ``g_max`` (units of the disc's radiance scale ``amp``), its scale height uniform on ``[H_lo_km, H_hi_km]``.
        Default ``(0.4, 6.0, 25.0)``: the glows of :mod:`jaxlimb.render.independent` (the Earth's haze at its limb);
        ``None`` for a body without an atmosphere.
    """

    band_px: float = 4.0
    arc_margin_deg: float = 30.0
    interior_ramp: bool = True
    center_floor_px: float = 0.0075
    sun_declination_max_deg: float | None = None
    unresolved_glow: tuple[float, float, float] | None = (0.4, 6.0, 25.0)

    def __post_init__(self) -> None:
        if not (isinstance(self.band_px, (int, float)) and math.isfinite(self.band_px) and self.band_px > 1.0):
            raise ConfigError(f"EllipsoidOptions.band_px must be a finite number > 1.0, got {self.band_px!r}")
        if not (isinstance(self.center_floor_px, (int, float)) and math.isfinite(self.center_floor_px)
                and 0.0 <= self.center_floor_px <= 1.0):
            raise ConfigError(f"EllipsoidOptions.center_floor_px must be in [0, 1] px, got {self.center_floor_px!r}")
        dmax = self.sun_declination_max_deg
        if dmax is not None and (isinstance(dmax, bool) or not (isinstance(dmax, (int, float)) and 0.0 <= dmax <= 90.0)):
            raise ConfigError("EllipsoidOptions.sun_declination_max_deg must be None or in [0, 90] deg, got "
                              f"{self.sun_declination_max_deg!r}")
        ug = self.unresolved_glow
        if ug is not None and not (isinstance(ug, tuple) and len(ug) == 3
                                   and all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in ug)
                                   and 0 < ug[1] <= ug[2]):
            raise ConfigError("EllipsoidOptions.unresolved_glow must be None or (g_max, H_lo_km, H_hi_km), all >= 0, "
                              f"0 < H_lo_km <= H_hi_km, got {ug!r}")
        if not (isinstance(self.arc_margin_deg, (int, float)) and 0 <= self.arc_margin_deg < 80):
            raise ConfigError(f"EllipsoidOptions.arc_margin_deg must be in [0, 80) deg, got {self.arc_margin_deg!r}")


@dataclass(frozen=True)
class LocateOptions:
    """How :func:`~jaxlimb.pipeline.locate` measures a limb.

    Attributes
    ----------
    front_end
        ``"gradient"`` (default: Richardson gradient, box filter, RANSAC, Taubin; Aerospace 2015 §4-5) or
        ``"scanline"`` (threshold, inertia axis, scan lines; illuminated-ellipsoid paper §IV-A, §VI).
    front_end_fallback
        ``True`` (default): when the front end finds no limb (Checks 2-4) on a variegated body (bright clouds on a
        darker disc, :func:`jaxlimb.imaging.crop.dark_surface_region`), or its circle proves off the limb, the other
        front end is tried (:func:`jaxlimb.pipeline.frame.candidates`); the measurement's ``front_end`` says which
        one answered.
    model
        ``"circle"`` (default): the circular sigmoid (CSF, Eq. 16) refinement; with a camera the limb is then
        refitted with the elliptical sigmoid whose axis ratio and orientation are those of the image of a sphere at
        the estimated place (the body-centre correction) and ``radius_px`` is the on-axis-equivalent apparent radius
        ``f tan(alpha)``.  ``"ellipse"``: an elliptical sigmoid (ESF, Sec. V-C) with centre, semi-axis, orientation
        and axis ratio all free (a non-spherical or unknown body); the measurement carries ``ellipse``.
    solver
        Name in :data:`jaxlimb.fitting.SOLVERS` (``"lm"`` default, ``"paper"``, ``"scipy"``, ...).
    estimate_k
        ``True`` (default, Aerospace 2015 §5-6): estimate the steepness ``k`` and the levels ``ymax``, ``ymin`` with
        the geometry.  ``False`` (illuminated-ellipsoid paper §VI, Table 1): hold ``k = 3`` and ``ymax``/``ymin`` at
        the means of the pixels at the annulus' inner/outer edges.
    profile
        ``"auto"`` (default): with the model ``"circle"`` and ``estimate_k`` on, the physical limb profile of a
        sunlit body when the hints give the Sun direction (:mod:`jaxlimb.pipeline.profile`; it removes the sigmoid's
        limb bias, 0.1-0.6 px on realistic Moons, ``benchmarks/locate_accuracy.py``), the limb-darkened disc when
        they say ``body = "sun"`` (:mod:`jaxlimb.pipeline.sphere.sun`), or the corona over an opaque disc when that
        disc is brightest at its limb (the EUV: :mod:`jaxlimb.pipeline.sphere.corona`); else the sigmoid.
        ``"sigmoid"``: the papers' sigmoid limb.  ``"lunar-lambert"``, ``"limb-darkened"``, ``"corona"``: that
        profile (circle model only).
        ``"albedo-field"``: the lunar-Lambert profile with the surface albedo an unknown Gaussian field, marginalised
        (:mod:`jaxlimb.pipeline.profile.albedo_field`; its covariance replaces the model-error terms; no widening to
        limb brightening, smear or glow; the sphere strategy: the Earth's ellipsoid keeps its own profile).  With
        ``"auto"`` a profile whose fitted lunar-Lambert weight ``L`` is outside the band of lunar-Lambert-like limbs,
        and not physical under the albedo field either (:func:`~jaxlimb.pipeline.profile.passes.in_band`), sends
        the measurement back to the sigmoid (``extras["profile_rejected"]``).
    min_lit_arc_deg
        Smallest arc (deg) of lit limb in the frame that is measured (the ``arc_too_short`` check of
        :mod:`jaxlimb.pipeline.checks`): a circle's centre error per unit of radial noise grows about as the
        inverse square of the arc.  ``None`` (default): 45 deg with the physical limb profile, 60 deg with the
        sigmoid.  Lower it to accept short arcs with their (large) covariance.
    max_steps
        Iteration limit of each least-squares fit (Check 5: no convergence).
    body_center_correction
        With a camera, convert the limb to the image of the body centre exactly (the elliptical refit and
        :func:`jaxlimb.geometry.navigation.sphere_from_ellipse`); ``False`` reports the circle centre.
    compute_crlb
        Add the Cramér--Rao bound at the estimate, with sigma-hat as the noise level.
    keep_pixels
        Keep the fitted pixel coordinates in ``LimbMeasurement.selected_pixels_rc`` (for figures; not part of
        the JSON output).
    max_center_sigma_px
        The stated tolerance on the centre: a measurement whose own 1-sigma (larger axis) exceeds it fails with
        :class:`~jaxlimb.pipeline.checks.CenterTooUncertainError` (default 1 px; ``None``: no limit, the
        covariance says how good it is).
    shape
        The body strategy (:class:`BodyShape`; default ``auto``: the hints' body decides).
    ellipsoid
        :class:`EllipsoidOptions` of the ellipsoid strategy (``None`` = defaults).
    gradient, scanline
        :class:`~jaxlimb.imaging.GradientOptions`, :class:`~jaxlimb.imaging.ScanlineOptions` of the front ends
        (``None`` = defaults).
    """

    front_end: str = "gradient"
    front_end_fallback: bool = True
    model: str = "circle"
    solver: str = "lm"
    estimate_k: bool = True
    profile: str = "auto"
    min_lit_arc_deg: float | None = None
    max_steps: int = 100
    body_center_correction: bool = True
    compute_crlb: bool = True
    keep_pixels: bool = True
    max_center_sigma_px: float | None = 1.0
    shape: BodyShape = BodyShape.AUTO
    ellipsoid: EllipsoidOptions | None = None
    gradient: GradientOptions | None = None
    scanline: ScanlineOptions | None = None

    def __post_init__(self) -> None:
        for name, kind in (("front_end", FrontEnd), ("model", LimbModelKind), ("profile", Profile), ("shape", BodyShape)):
            object.__setattr__(self, name, kind.parse(name, getattr(self, name)))
        if self.solver not in SOLVERS:
            raise ConfigError(f"LocateOptions.solver must be one of {sorted(SOLVERS)}, got {self.solver!r}")
        _pos("max_center_sigma_px", self.max_center_sigma_px, allow_none=True)
        if self.profile in ("lunar-lambert", "albedo-field", "limb-darkened", "corona") and self.model != "circle":
            raise ConfigError(f"LocateOptions.profile = {self.profile!r} supports model = 'circle' only")
        _pos("min_lit_arc_deg", self.min_lit_arc_deg, allow_zero=True, allow_none=True)
        if self.min_lit_arc_deg is not None and self.min_lit_arc_deg > 360:
            raise ConfigError(f"LocateOptions.min_lit_arc_deg must be in [0, 360], got {self.min_lit_arc_deg!r}")
        if isinstance(self.max_steps, bool) or not isinstance(self.max_steps, int) or self.max_steps < 1:
            raise ConfigError(f"LocateOptions.max_steps must be an integer >= 1, got {self.max_steps!r}")
        for name, kind in (("ellipsoid", EllipsoidOptions), ("gradient", GradientOptions), ("scanline", ScanlineOptions)):
            v = getattr(self, name)
            if v is not None and not isinstance(v, kind):
                raise ConfigError(f"LocateOptions.{name} must be a {kind.__name__} or None, got {type(v).__name__}")

    @property
    def ellipsoid_options(self) -> EllipsoidOptions:
        """The ellipsoid strategy's settings (the defaults when ``ellipsoid`` is ``None``)."""
        return self.ellipsoid if self.ellipsoid is not None else EllipsoidOptions()


__all__ = ["FRONT_ENDS", "LIMB_MODELS", "PROFILES", "BodyShape", "EllipsoidOptions", "FrontEnd", "LimbModelKind",
           "LocateOptions", "Profile"]
