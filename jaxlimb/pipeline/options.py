"""Settings of :func:`jaxlimb.pipeline.locate` (one frozen dataclass, every field documented)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from .._validate import NON_NEGATIVE, POSITIVE, number
from ..errors import ConfigError
from ..fitting.solvers import SOLVERS


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
    LIMB_DARKENED = "limb-darkened"


class BodyShape(_Choice):
    """The body strategy of :func:`~jaxlimb.pipeline.locate`: ``auto`` (the Sun: ``disc``; the Earth:
    ``ellipsoid``; any other body: ``sphere``), or one of them."""

    AUTO = "auto"
    SPHERE = "sphere"
    ELLIPSOID = "ellipsoid"
    DISC = "disc"


FRONT_ENDS = tuple(m.value for m in FrontEnd)
LIMB_MODELS = tuple(m.value for m in LimbModelKind)
PROFILES = tuple(m.value for m in Profile)


def _pos(name: str, v: object, *, allow_zero: bool = False, allow_none: bool = False) -> None:
    if v is None and allow_none:
        return
    number(v, f"LocateOptions.{name}", NON_NEGATIVE if allow_zero else POSITIVE)


@dataclass(frozen=True)
class LocateOptions:
    """How :func:`~jaxlimb.pipeline.locate` measures a limb.

    Attributes
    ----------
    front_end
        ``"gradient"`` (default: Richardson gradient, box filter, RANSAC, Taubin; Aerospace
        2015 §4-5) or ``"scanline"`` (threshold, inertia axis, scan lines; illuminated-ellipsoid
        paper §IV-A, §VI).
    front_end_fallback
        ``True`` (default): when the front end finds no limb (Checks 2-4: too few candidates, no
        consistent circle, a radius outside the prior, a circle that leaves the lit region outside) on a
        variegated body (bright clouds on a darker disc, :func:`jaxlimb.imaging.crop.dark_surface_region`),
        the other front end is tried (:func:`jaxlimb.pipeline.frame.candidates`); the measurement's
        ``front_end`` says which one answered.  The gradient front end's strongest edges can all lie inside
        such a body (the Earth's cloud edges at low phase) where the scan lines of the thresholded disc
        still find its outline; on other frames the first refusal is the answer.
    model
        ``"circle"`` (default): the circular sigmoid (CSF, Eq. 16) refinement; with a camera the
        limb is then refitted with the elliptical sigmoid whose axis ratio and orientation are
        those of the image of a sphere at the estimated place (the body-centre correction) and
        ``radius_px`` is the on-axis-equivalent apparent radius ``f tan(alpha)``.  ``"ellipse"``:
        an elliptical sigmoid (ESF, Sec. V-C) with centre, semi-axis, orientation and axis
        ratio all free (a non-spherical or unknown body); the measurement carries ``ellipse``.
    solver
        Name in :data:`jaxlimb.fitting.SOLVERS` (``"lm"`` default, ``"paper"``, ``"scipy"``, ...).
    estimate_k
        ``True`` (default, Aerospace 2015 §5-6): estimate the steepness ``k`` and the levels
        ``ymax``, ``ymin`` with the geometry (6 free parameters for the CSF).  ``False``
        (illuminated-ellipsoid paper §VI, Table 1): hold ``k = k_fixed`` and ``ymax``/``ymin``
        at the means of the pixels at the annulus' inner/outer edges (3 free parameters).
    k_fixed
        The steepness (1/px) used when ``estimate_k`` is ``False`` (paper: 3).
    profile
        ``"auto"`` (default): with the model ``"circle"`` and ``estimate_k`` on, the physical
        limb profile of a sunlit body when the hints give the Sun direction, the limb-darkened
        disc when they say ``body = "sun"``; else the sigmoid.  ``"limb-darkened"``: after
        the sigmoid, refit a full annulus with the blurred quadratic limb-darkening law of a
        self-luminous disc (:mod:`jaxlimb.pipeline.sphere.sun`; the SDO/HMI radius error
        goes from -0.156 px with the sigmoid to +0.039 px).  ``"sigmoid"``: the papers' sigmoid
        limb.  ``"lunar-lambert"``: after the sigmoid, refit the same pixels with the physical
        limb profile of a lunar-Lambert sphere blurred by a Gaussian PSF
        (:mod:`jaxlimb.pipeline.profile`; needs the Sun direction in the hints).  It removes
        the sigmoid's limb bias (0.1-0.6 px on realistic Moons, growing with phase; measured
        in ``benchmarks/locate_accuracy.py``); circle model only.
    lunar_lambert_L
        The weight ``L`` of the lunar-Lambert law ``I = L 2 mu0/(mu0 + mu) + (1 - L) mu0`` used
        by the profile (``1``: Lommel-Seeliger, ``0``: Lambert), held fixed; ``None`` (default):
        ``L`` is estimated with the limb, starting from McEwen's ``L(phase)``
        (:func:`jaxlimb.models.lunar_lambert.lunar_lambert_weight`).  With ``profile="auto"`` a
        fitted ``L`` outside ``[-0.1, 1.1]`` (a limb no such law describes, e.g. a flat disc)
        sends the measurement back to the sigmoid (``extras["profile_rejected"]``).
    min_lit_arc_deg
        Smallest arc (deg) of lit limb in the frame that is measured (the ``arc_too_short``
        check of :mod:`jaxlimb.pipeline.checks`): a circle's centre error per unit of radial
        noise grows about as the inverse square of the arc (25x a full circle's at 60 deg, 98x
        at 30 deg).  ``None`` (default): 45 deg with the physical limb profile, 60 deg with the
        sigmoid (shorter arcs of cropped Moons were off by 0.2-0.6 px and 0.3-15 px).  Lower it
        to accept short arcs with their (large) covariance.
    normalize_levels
        Divide each angular bin of the annulus by its own inside-outside contrast (and weight
        it by that contrast) before the fit (default ``True``; :class:`jaxlimb.pipeline.stages.FitData`):
        the lit limb of the Moon fades toward the horns, which biases a one-level sigmoid by px.
        ``False`` fits the raw intensities as the papers do.
    annulus_px
        Half-width ``dr`` (px) of the annulus ``r_hat +- dr`` of pixels fitted; ``None``
        (default) applies the rule of :func:`jaxlimb.pipeline.sphere.annulus.annulus_halfwidth`:
        ``dr = max(annulus_min_px, annulus_frac * r_hat, 4 * rms_taubin)``, widened after a
        first fit to ``4.5 * 1.7 / k`` when the fitted edge is broader (1.7/k is the Gaussian
        sigma equivalent to a logistic of steepness k), capped at ``max(annulus_min_px, r_hat/2)``.
    annulus_min_px
        Smallest half-width of the annulus (px, default 6: covers +-4 sigma of a 1.5 px blur).
    annulus_frac
        Half-width as a fraction of the initial radius (default 0.02: a few px for the
        paper's 50-500 px Moons; the initial radius is good to ~1 % of itself).
    horn_margin_deg
        With a known Sun direction, the lit limb is the half-circle facing the Sun; the
        pixels within this angle of the horns (where the limb meets the terminator and the
        brightness falls) are left out (default 10 deg; more for a thin crescent, see
        :func:`jaxlimb.pipeline.sphere.annulus.lit_halfangle`).
    min_lit_contrast_frac
        Angular bins (``angular_bin_deg`` wide) of the annulus whose inside-minus-outside
        contrast is below this fraction of the 90th-percentile bin contrast are dropped
        (dark limb, terminator, beyond the horns; default 0.3).
    angular_bin_deg
        Width of those angular bins (deg, default 5).
    max_edge_offset_px
        Bins whose edge (estimated from the bin's mean normalised intensity) lies more than
        this inside the 75th percentile of the bins' edges are dropped (terminator, dark limb;
        default 0.75 px; ``None`` disables the test).
    outlier_sigma
        Pixels whose residual after the first fit exceeds this many sigma-hat are dropped
        and the fit repeated (stars, hot pixels, craters; default 5).
    max_outlier_fraction
        Check 3 in the refinement: more residual outliers than this fraction of the annulus
        raises :class:`~jaxlimb.errors.TooManyOutliersError` (default 0.2).
    max_jump_px
        Check 5: largest displacement (px) of the fitted limb from the front end's (Taubin)
        circle anywhere on the fitted arc; ``None`` (default) = ``max(2, dr / 2)``: a limb
        that moved by half the annulus half-width has left the well-sampled middle of the
        annulus, so the fit is no longer measuring the edge the front end found.
    max_steps
        Iteration limit of each least-squares fit (Check 5: no convergence).
    body_center_correction
        With a camera, convert the limb to the image of the body centre exactly (the
        elliptical refit and :func:`jaxlimb.geometry.navigation.sphere_from_ellipse`);
        ``False`` reports the circle centre (for studies of the correction).
    compute_crlb
        Add the Cramér--Rao bound at the estimate, with sigma-hat as the noise level.
    border_px
        Pixels within this distance of the frame edge are not fitted (default 0).
    keep_pixels
        Keep the fitted pixel coordinates in ``LimbMeasurement.selected_pixels_rc`` (for
        figures; not part of the JSON output).
    max_psf_sigma_px
        A fit whose edge blur (Gaussian PSF sigma, or the sigmoid's ``1.7/k`` less the pixel box)
        exceeds this is not a limb: :class:`~jaxlimb.pipeline.checks.NonPhysicalFitError` (default 5 px).
    max_center_sigma_px
        The stated tolerance on the centre: a measurement whose own 1-sigma (larger axis) exceeds it
        fails with :class:`~jaxlimb.pipeline.checks.CenterTooUncertainError` (default 1 px; ``None``:
        no limit, the covariance says how good it is).
    shape
        The body strategy (:class:`BodyShape`; default ``auto``: the hints' body decides).
    ellipsoid
        :class:`~jaxlimb.pipeline.ellipsoid.options.EllipsoidOptions` of the ellipsoid strategy (``None`` = defaults).
    gradient
        :class:`~jaxlimb.imaging.GradientOptions` (``None`` = defaults).
    scanline
        :class:`~jaxlimb.imaging.ScanlineOptions` (``None`` = defaults).
    """

    front_end: str = "gradient"
    front_end_fallback: bool = True
    model: str = "circle"
    solver: str = "lm"
    estimate_k: bool = True
    k_fixed: float = 3.0
    profile: str = "auto"
    lunar_lambert_L: float | None = None
    min_lit_arc_deg: float | None = None
    normalize_levels: bool = True
    annulus_px: float | None = None
    annulus_min_px: float = 6.0
    annulus_frac: float = 0.02
    horn_margin_deg: float = 10.0
    min_lit_contrast_frac: float = 0.3
    angular_bin_deg: float = 5.0
    max_edge_offset_px: float | None = 0.75
    outlier_sigma: float = 5.0
    max_outlier_fraction: float = 0.2
    max_jump_px: float | None = None
    max_steps: int = 100
    body_center_correction: bool = True
    compute_crlb: bool = True
    border_px: int = 0
    keep_pixels: bool = True
    max_psf_sigma_px: float = 5.0
    max_center_sigma_px: float | None = 1.0
    shape: BodyShape = BodyShape.AUTO
    ellipsoid: object | None = None
    gradient: object | None = None
    scanline: object | None = None

    def __post_init__(self) -> None:
        for name, kind in (("front_end", FrontEnd), ("model", LimbModelKind), ("profile", Profile), ("shape", BodyShape)):
            object.__setattr__(self, name, kind.parse(name, getattr(self, name)))

        if self.solver not in SOLVERS:
            raise ConfigError(f"LocateOptions.solver must be one of {sorted(SOLVERS)}, got {self.solver!r}")
        _pos("k_fixed", self.k_fixed)
        _pos("max_psf_sigma_px", self.max_psf_sigma_px)
        _pos("max_center_sigma_px", self.max_center_sigma_px, allow_none=True)
        if self.lunar_lambert_L is not None:
            _pos("lunar_lambert_L", self.lunar_lambert_L, allow_zero=True)
            if self.lunar_lambert_L > 1:
                raise ConfigError(f"LocateOptions.lunar_lambert_L must be in [0, 1] or None, got {self.lunar_lambert_L!r}")
        if self.profile in ("lunar-lambert", "limb-darkened") and self.model != "circle":
            raise ConfigError(f"LocateOptions.profile = {self.profile!r} supports model = 'circle' only")
        _pos("min_lit_arc_deg", self.min_lit_arc_deg, allow_zero=True, allow_none=True)
        if self.min_lit_arc_deg is not None and self.min_lit_arc_deg > 360:
            raise ConfigError(f"LocateOptions.min_lit_arc_deg must be in [0, 360], got {self.min_lit_arc_deg!r}")
        _pos("annulus_px", self.annulus_px, allow_none=True)
        _pos("annulus_min_px", self.annulus_min_px)
        _pos("annulus_frac", self.annulus_frac, allow_zero=True)
        _pos("horn_margin_deg", self.horn_margin_deg, allow_zero=True)
        if self.horn_margin_deg >= 90:
            raise ConfigError(f"LocateOptions.horn_margin_deg must be in [0, 90), got {self.horn_margin_deg!r}")
        _pos("min_lit_contrast_frac", self.min_lit_contrast_frac, allow_zero=True)
        if self.min_lit_contrast_frac >= 1:
            raise ConfigError(f"LocateOptions.min_lit_contrast_frac must be in [0, 1), got {self.min_lit_contrast_frac!r}")
        _pos("angular_bin_deg", self.angular_bin_deg)
        _pos("max_edge_offset_px", self.max_edge_offset_px, allow_none=True)
        _pos("outlier_sigma", self.outlier_sigma)
        _pos("max_outlier_fraction", self.max_outlier_fraction, allow_zero=True)
        if self.max_outlier_fraction > 1:
            raise ConfigError(f"LocateOptions.max_outlier_fraction must be in [0, 1], got {self.max_outlier_fraction!r}")
        _pos("max_jump_px", self.max_jump_px, allow_none=True)
        if isinstance(self.max_steps, bool) or not isinstance(self.max_steps, int) or self.max_steps < 1:
            raise ConfigError(f"LocateOptions.max_steps must be an integer >= 1, got {self.max_steps!r}")
        if isinstance(self.border_px, bool) or not isinstance(self.border_px, int) or self.border_px < 0:
            raise ConfigError(f"LocateOptions.border_px must be an integer >= 0, got {self.border_px!r}")


__all__ = ["FRONT_ENDS", "LIMB_MODELS", "PROFILES", "BodyShape", "FrontEnd", "LimbModelKind", "LocateOptions",
           "Profile"]
