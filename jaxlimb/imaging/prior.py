r"""The prior: expected radius, illumination parameter and the derived settings.

Section 3 of the Aerospace 2015 paper ("Expected radius and illumination
parameter").  Inputs are a :class:`~jaxlimb.geometry.camera.Camera` and the
navigation filter's :class:`Hints` (docs/design.md hints JSON).  When neither is
available the prior is measured on the image itself (:func:`prior_from_image`).

Expected radius, Eq. (1):  :math:`p_r = \frac{f}{d} \frac{R_m}{\sqrt{|r_o|^2 - R_m^2}}`.

Illumination angle, Eq. (2): :math:`\vartheta = \arccos(\hat r_s \cdot \hat r_o)`
with :math:`\hat r_s` the Sun-to-body ray direction (``-sun_dir_camera``) and
:math:`\hat r_o` the observer-to-body direction (the line of sight); it is the
phase angle (0 = full).

Cases (Eq. 3-14), with :math:`\sin\alpha_m = R_m/|r_o|` and the critical distance
:math:`r_{cr} \sin\vartheta = R_m` (Eq. 4):

* :math:`|r_o| < r_{cr}`: full (:math:`p_i = 2 p_r`, :math:`\vartheta < \pi/2`) or new
  (:math:`p_i = 0`) (Eq. 5);
* gibbous, :math:`|r_o| > r_{cr}`, :math:`\vartheta < \pi/2` (Eq. 6-10):
  :math:`x^2 = |r_o|^2 + R_m^2 - 2|r_o| R_m \sin\vartheta`,
  :math:`\sin\alpha_e = R_m\cos\vartheta / x`,
  :math:`p_i = (1 + \tan\alpha_e/\tan\alpha_m)\, p_r`;
* crescent, :math:`\vartheta > \pi/2` (Eq. 11-14): as above with
  :math:`\sin\alpha_e = -R_m\cos\vartheta/x` and :math:`p_i = (1 - \tan\alpha_e/\tan\alpha_m)\, p_r`.

Decision (range unknown): when only ``expected_radius_px`` is given (no range
nor body radius) the far-field limit of Eq. (10)/(14) is used,
:math:`p_i = p_r (1 + \cos\vartheta)` (as :math:`|r_o| \to \infty`,
:math:`x \to |r_o|`, :math:`\tan\alpha_e/\tan\alpha_m \to \pm\cos\vartheta`).
When the range is unknown but the body radius is, :math:`|r_o|` is recovered
from :math:`p_r` by inverting Eq. (1).

Derived settings (Eq. 15-17 and §3): ``N = k pi p_r`` with
``k = 2 (1 + (p_i - 10)/(2 p_r - 10))`` clipped to [2, 4]; box size
``s = ceil(0.8 p_r)`` (odd, in [3, 21]); RANSAC distance ``d_max = 5 p_r/100``;
``N_T = N_1 (N_1 - 1)(N_1 - 2)/30`` capped at 500.

Decisions (thresholds the paper leaves open, all in :class:`PriorOptions`):
``N`` is capped at 1500 (the paper's §6 maximum) and floored at 50; ``d_max``
has a floor of 2 px (integer pixel positions scatter by ~0.5 px, and for
``p_r < 40`` the literal ``5 p_r/100`` is below 2 px); the box size follows
the printed ``0.8 p_r`` (it reaches the 21 px cap at ``p_r = 26``).
Check 1 thresholds: diameter below 10 px -> too small; a radius above the
half-diagonal of the frame (body filling it) -> too big; ``p_i`` below 3 px ->
too thin (new moon / hair-thin crescent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError, TooBigError, TooSmallError, TooThinError
from ..geometry.camera import Camera
from ..geometry.hints import Hints
from .crop import MIN_DIAMETER_PX, detect_body

@dataclass(frozen=True)
class PriorOptions:
    """Thresholds of §3 (Check 1) and caps of the derived settings.

    Attributes
    ----------
    min_diameter_px
        Check 1: a body with expected diameter below this is too small (px, default 10).
    max_radius_frac_of_halfdiag
        Check 1: expected radius above this fraction of the frame half-diagonal is too big (default 1.0).
    min_illumination_px
        Check 1/2: illumination parameter ``p_i`` below this is too thin (px, default 3).
    min_points, max_points
        Bounds of N (Eq. 15); the paper's §6 uses 1500 as the maximum.
    box_factor
        ``s = ceil(box_factor * p_r)`` (paper: 0.8); ``box_min``, ``box_max`` its limits (3, 21).
    ransac_dmax_frac
        RANSAC distance as a fraction of ``p_r`` (paper: 5/100); ``ransac_dmax_min`` its floor (px, 2).
    ransac_max_tests
        Cap of ``N_T`` (Eq. 17; paper: 500).
    default_uncertainty_frac
        Radius uncertainty assumed when hints give a radius without one (0.2), and
        ``image_uncertainty_frac`` for a prior measured on the image (0.35).
    """

    min_diameter_px: float = MIN_DIAMETER_PX
    max_radius_frac_of_halfdiag: float = 1.0
    min_illumination_px: float = 3.0
    min_points: int = 50
    max_points: int = 1500
    box_factor: float = 0.8
    box_min: int = 3
    box_max: int = 21
    ransac_dmax_frac: float = 0.05
    ransac_dmax_min: float = 2.0
    ransac_max_tests: int = 500
    default_uncertainty_frac: float = 0.2
    image_uncertainty_frac: float = 0.35

    def __post_init__(self) -> None:
        for name in ("min_diameter_px", "min_illumination_px", "box_factor", "ransac_dmax_frac", "ransac_dmax_min",
                     "max_radius_frac_of_halfdiag", "default_uncertainty_frac", "image_uncertainty_frac"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"PriorOptions.{name} must be a finite number >= 0, got {v!r}")
        if not (3 <= self.min_points <= self.max_points):
            raise ConfigError(f"PriorOptions needs 3 <= min_points <= max_points, got {self.min_points}, {self.max_points}")
        if not (3 <= self.box_min <= self.box_max):
            raise ConfigError(f"PriorOptions needs 3 <= box_min <= box_max, got {self.box_min}, {self.box_max}")
        if self.ransac_max_tests < 1:
            raise ConfigError(f"PriorOptions.ransac_max_tests must be >= 1, got {self.ransac_max_tests}")


@dataclass(frozen=True)
class Prior:
    """Expected appearance of the body (§3).

    Attributes
    ----------
    expected_radius_px
        :math:`p_r` (px).
    radius_uncertainty_frac
        Relative uncertainty of ``expected_radius_px``.
    illumination_px
        :math:`p_i` (px), the lit cross-length at the thickest point (0 .. 2 p_r).
    phase_rad
        :math:`\\vartheta` (rad), or ``None`` if unknown.
    case
        ``"full"``, ``"new"``, ``"gibbous"``, ``"crescent"`` or ``"unknown"``.
    sun_dir_rc
        Unit image-plane direction ``(d_row, d_col)`` of the Sun seen from the body
        centre (the lit limb faces it), or ``None`` (unknown, or Sun along the LOS).
    source
        ``"hints"`` or ``"image"``.
    radius_bounds_px
        Explicit ``(lo, hi)`` radius band (px; ``hi`` may be ``inf``) overriding
        the one derived from the uncertainty; set by :func:`prior_from_image`.
    """

    expected_radius_px: float
    radius_uncertainty_frac: float
    illumination_px: float
    phase_rad: float | None = None
    case: str = "unknown"
    sun_dir_rc: tuple[float, float] | None = None
    source: str = "hints"
    radius_bounds_px: tuple[float, float] | None = None

    @property
    def radius_range(self) -> tuple[float, float]:
        """The RANSAC / Check 4 radius band: ``radius_bounds_px`` if set, else
        ``p_r (1 -/+ 3 u)`` clipped at 0.2 p_r below."""
        if self.radius_bounds_px is not None:
            return self.radius_bounds_px
        u = self.radius_uncertainty_frac
        return (self.expected_radius_px * max(0.2, 1 - 3 * u), self.expected_radius_px * (1 + 3 * u))


@dataclass(frozen=True)
class Settings:
    """Settings derived from the prior (Eq. 15-17 and §3).

    Attributes
    ----------
    n_points
        N, number of strongest-gradient pixels analysed (Eq. 15-16).
    box_size
        s, side of the box of the box-based outlier filter (odd).
    ransac_dmax
        RANSAC inlier distance (px).
    """

    n_points: int
    box_size: int
    ransac_dmax: float


def illumination_parameter(pr: float, phase: float, range_km: float | None = None, radius_km: float | None = None):
    """:math:`p_i` and the case name from Eq. (3)-(14).

    Returns
    -------
    (p_i, case) with ``case`` in ``{"full", "new", "gibbous", "crescent"}``.
    """
    if not (0.0 <= phase <= math.pi):
        raise ConfigError(f"phase must be in [0, pi] rad, got {phase!r}")
    if range_km is None or radius_km is None:
        # far-field limit of Eq. (10)/(14)
        pi_ = pr * (1.0 + math.cos(phase))
        if phase == 0:
            return 2 * pr, "full"
        return pi_, ("gibbous" if phase < math.pi / 2 else "crescent")
    ro, Rm = float(range_km), float(radius_km)
    if ro <= Rm:
        raise ConfigError(f"range_prior_km must exceed the body radius {Rm} km, got {ro}")
    s = math.sin(phase)
    r_cr = Rm / s if s > 0 else math.inf  # Eq. (4)
    if ro < r_cr:  # Eq. (5)
        return (2.0 * pr, "full") if phase < math.pi / 2 else (0.0, "new")
    tan_am = math.tan(math.asin(Rm / ro))  # Eq. (3)
    x = math.sqrt(ro * ro + Rm * Rm - 2 * ro * Rm * s)  # Eq. (7)/(12)
    if phase < math.pi / 2:
        ae = math.asin(min(1.0, Rm * math.cos(phase) / x))  # Eq. (8)
        return (1 + math.tan(ae) / tan_am) * pr, "gibbous"  # Eq. (10)
    ae = math.asin(min(1.0, -Rm * math.cos(phase) / x))  # Eq. (13)
    return max(0.0, (1 - math.tan(ae) / tan_am) * pr), "crescent"  # Eq. (14)


def sun_direction_image(sun_dir_camera, camera: Camera | None = None, center_rc=None, min_norm: float = 0.02):
    """Image-plane direction ``(d_row, d_col)`` toward which the lit limb faces.

    The projection of ``sun_dir_camera`` (body -> Sun, camera frame) at the body.
    With a camera and an estimate of the body's image centre the exact
    derivative of the pinhole projection is used (body off the boresight);
    otherwise ``(s_y, s_x)`` (+x -> +col, +y -> +row).  Returns ``None`` when the
    projected length is below ``min_norm`` (Sun behind the observer or behind the
    body: no preferred side).
    """
    s = np.asarray(sun_dir_camera, float)
    s = s / np.linalg.norm(s)
    if camera is not None and center_rc is not None:
        u = camera.los(np.asarray(center_rc, float))
        # component of s perpendicular to the LOS, mapped through d(project)/d(xyz) at u
        sp = s - (s @ u) * u
        if np.linalg.norm(sp) < min_norm:
            return None
        f = camera.focal_px
        x, y, z = u
        J = np.array([[0.0, f / z, -f * y / z**2], [f / z, 0.0, -f * x / z**2]])  # (row, col) wrt (x, y, z)
        d = J @ sp
    else:
        d = np.array([s[1], s[0]])
        if np.linalg.norm(d) < min_norm:
            return None
    n = np.linalg.norm(d)
    if n == 0:
        return None
    return (float(d[0] / n), float(d[1] / n))


def prior_from_hints(
    hints: Hints,
    camera: Camera | None = None,
    *,
    center_rc=None,
    options: PriorOptions | None = None,
    check: bool = True,
) -> Prior | None:
    """The §3 prior from hints (+ camera); ``None`` when the hints fix no radius.

    The line of sight is the boresight unless ``center_rc`` (an image estimate of
    the body centre) is given.  With ``check`` the Check-1 tests run
    (:func:`check_prior`).
    """
    opt = options or PriorOptions()
    Rkm = hints.radius_km()
    pr = hints.expected_radius_px
    rng = hints.range_prior_km
    if pr is None and rng is not None and Rkm is not None and camera is not None:
        if rng <= Rkm:
            raise ConfigError(f"hints `range_prior_km` must exceed the body radius {Rkm:.6g} km, got {rng!r}")
        pr = camera.focal_px * Rkm / math.sqrt(rng * rng - Rkm * Rkm)  # Eq. (1)
    if pr is None:
        return None
    unc = hints.expected_radius_uncertainty_frac or opt.default_uncertainty_frac
    if rng is None and Rkm is not None and camera is not None:
        rng = Rkm / math.sin(math.atan(pr / camera.focal_px))  # inverse of Eq. (1)
    phase = None
    case = "unknown"
    pi_ = 2.0 * pr
    sun_rc = None
    if hints.sun_dir_camera is not None:
        s = np.asarray(hints.sun_dir_camera)
        u = camera.los(np.asarray(center_rc, float)) if (camera is not None and center_rc is not None) else np.array([0, 0, 1.0])
        phase = float(np.arccos(np.clip(-s @ u, -1.0, 1.0)))  # Eq. (2)
        pi_, case = illumination_parameter(pr, phase, rng if Rkm is not None else None, Rkm)
        sun_rc = sun_direction_image(s, camera, center_rc)
    prior = Prior(float(pr), float(unc), float(pi_), phase, case, sun_rc, "hints")
    if check:
        check_prior(prior, camera.shape if camera is not None else None, opt)
    return prior


def check_prior(prior: Prior, image_shape: tuple[int, int] | None = None, options: PriorOptions | None = None) -> None:
    """Check 1 of §3 on the prior: too small, too big (fills the frame), too thin / new.

    Raises
    ------
    TooSmallError, TooBigError, TooThinError
    """
    opt = options or PriorOptions()
    pr = prior.expected_radius_px
    if 2 * pr < opt.min_diameter_px:
        raise TooSmallError(
            f"expected apparent diameter 2*p_r = {2 * pr:.3g} px is below min_diameter_px = {opt.min_diameter_px:g} px"
        )
    if image_shape is not None:
        half_diag = 0.5 * math.hypot(*image_shape)
        if pr > opt.max_radius_frac_of_halfdiag * half_diag:
            raise TooBigError(
                f"expected radius p_r = {pr:.4g} px exceeds {opt.max_radius_frac_of_halfdiag:g} x the frame "
                f"half-diagonal ({half_diag:.4g} px): the body fills the image"
            )
    if prior.illumination_px < opt.min_illumination_px:
        raise TooThinError(
            f"illumination parameter p_i = {prior.illumination_px:.3g} px (case {prior.case!r}) is below "
            f"min_illumination_px = {opt.min_illumination_px:g} px: new or too thin a crescent"
        )


def derived_settings(prior: Prior, options: PriorOptions | None = None) -> Settings:
    """N (Eq. 15-16), box size and RANSAC distance from :math:`p_r`, :math:`p_i`."""
    opt = options or PriorOptions()
    pr, pi_ = prior.expected_radius_px, prior.illumination_px
    den = 2 * pr - 10
    k = 2.0 * (1.0 + (pi_ - 10.0) / den) if den > 0 else 2.0  # Eq. (16)
    k = min(4.0, max(2.0, k))
    n = int(math.ceil(k * math.pi * pr))  # Eq. (15)
    n = max(opt.min_points, min(opt.max_points, n))
    s = int(math.ceil(opt.box_factor * pr))
    s = s + 1 if s % 2 == 0 else s
    s = max(opt.box_min, min(opt.box_max if opt.box_max % 2 else opt.box_max - 1, s))
    dmax = max(opt.ransac_dmax_min, opt.ransac_dmax_frac * pr)
    return Settings(n_points=n, box_size=s, ransac_dmax=float(dmax))


def ransac_tests(n1: int, options: PriorOptions | None = None) -> int:
    """:math:`N_T = \\binom{N_1}{3}/5 = N_1(N_1-1)(N_1-2)/30` capped at 500 (Eq. 17), at least 1."""
    opt = options or PriorOptions()
    return int(max(1, min(opt.ransac_max_tests, n1 * (n1 - 1) * (n1 - 2) // 30)))


def prior_from_image(image: np.ndarray, options: PriorOptions | None = None, region=None) -> Prior:
    """A prior measured on the image when no camera/hints are given.

    Uses :func:`jaxlimb.imaging.crop.detect_body`: the half-extent of the lit
    region along its major axis estimates :math:`p_r` (the lit region of a
    full, gibbous or crescent body spans one diameter across the Sun direction),
    twice the largest inscribed-circle radius estimates :math:`p_i`, and
    :math:`\\cos\\vartheta \\approx p_i/p_r - 1`.  The uncertainty is
    ``image_uncertainty_frac`` (default 0.35).

    Radius band (decision): the lit region of a sphere never spans more than
    one diameter, and at any phase its bright limb spans (nearly) a full
    diameter across the Sun direction, so ``[0.85 p_r - 1, 1.6 p_r]``; when the
    region touches the frame edge (cropped body) the extent is only a lower
    bound and the band is ``[0.85 p_r - 1, inf)``.  This is what keeps a circle
    through terminator points, or a small arc, from being accepted.
    """

    opt = options or PriorOptions()
    reg = region if region is not None else detect_body(image)
    pr = max(0.5 * reg.extent_major_px, 0.5 * reg.thickness_px, 1.0)
    pi_ = min(reg.thickness_px, 2 * pr)
    cos_t = min(1.0, max(-1.0, pi_ / pr - 1.0))
    phase = math.acos(cos_t)
    case = "full" if phase < 0.2 else ("gibbous" if phase < math.pi / 2 else "crescent")
    unc = 1.0 if reg.touches_border else opt.image_uncertainty_frac
    lo = max(1.0, 0.85 * pr - 1.0)
    hi = math.inf if reg.touches_border else 1.6 * pr
    return Prior(pr, unc, pi_, phase, case, None, "image", (lo, hi))


__all__ = [
    "Prior",
    "PriorOptions",
    "Settings",
    "check_prior",
    "derived_settings",
    "illumination_parameter",
    "prior_from_hints",
    "prior_from_image",
    "ransac_tests",
    "sun_direction_image",
]
