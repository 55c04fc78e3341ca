r"""Earth pipeline: elliptical-sigmoid limb fit, centre offset and range iteration (§IV, Fig. 2).

Mortari, D'Souza & Zanetti, "Image Processing of Illuminated Ellipsoid" (J. Spacecraft and
Rockets 53(3), 2016, doi:10.2514/1.A33342), §III-IV and §V-C; the flowchart of Fig. 1 with the
Earth branch of step 5 and the position loop of Fig. 2.

Steps of :func:`locate_earth`
-----------------------------
1. **Limb candidates.**  One of the two front ends of :mod:`jaxlimb.imaging` (default the
   gradient + box filter + RANSAC + Taubin one of the Aerospace 2015 paper): limb points of the
   *lit* limb, an initial circle and the lit direction.  The Earth is a circle to 0.34 %
   (flattening) so the RANSAC circle accepts its limb; terminator points are rejected by RANSAC
   and by the lit-arc selection below.  The range prior (``range_prior_km``) or, without it,
   the circle radius (inverse of Eq. 1 of Aerospace 2015) starts the loop.
2. **Prior geometry -> rho, theta (Eq. 2-9).**  With ``R_body_to_camera`` known, the predicted
   body centre ``q_k = D_k u_k`` (camera frame) gives the limb cone
   ``M_c = (A q)(A q)^T - (q^T A q - 1) A``, ``A = R J R^T`` (Eq. 2 rotated to the camera) and
   its image conic ``C = -K^{-T} M_c K^{-1}``
   (:func:`jaxlimb.geometry.ellipsoid.image_conic`); the image ellipse's axis ratio ``rho`` and
   orientation ``theta`` are held fixed in the fit (the paper's choice: "rho can be well
   estimated using the estimated position and Eq. (9)").  The image ratio includes the
   perspective elongation off the boresight, which the cone's own ratio (Eq. 9) does not.
3. **Elliptical edge fit (§V-C).**  Pixels in a band of half-width ``band_px`` about the
   current ellipse and inside the lit arc (``arc_margin_deg`` off each horn); free
   ``(r0, c0, a, k, ymax, ymin)`` (or also ``rho, theta`` for the free ellipse, below).  By
   default the model is :data:`ELLIPSE_RAMP` (:func:`ellipse_ramp_intensity`): the paper's
   elliptical sigmoid with a Gaussian kernel, an interior brightness profile ``g_2 sqrt(u) +
   g u`` and a limb level varying along the arc; the paper's flat-topped ESF
   (``interior_ramp=False``) is biased toward the Sun by 0.2-4 px on gibbous renders.
4. **Measured cone.**  The fitted image ellipse is lifted back to its cone
   ``M_c \propto -K^T C K`` (:func:`image_ellipse_cone`): the eigenvector of the positive
   eigenvalue is the measured cone axis ``v_c = C_ci C_ie [0, 0, 1]`` (the "ellipse-centre
   direction" of §IV), and ``b' = \sqrt{\lambda_3 / (\lambda_3 + |\lambda_2|)}`` (Eq. 8 written
   with eigenvalues: ``a' = \xi_1/\sqrt{\xi_1^2+\xi_3^2} = (1 + |\lambda_1|/\lambda_3)^{-1/2}``).
5. **Range iteration (Fig. 2).**  :func:`jaxlimb.geometry.earth.earth_range_iteration` in the
   camera frame (pole ``R_body_to_camera [0,0,1]``): rotate ``v_c`` by ``gamma_off(p_k)``,
   compare the meridian angle ``dtheta_hat(p_k)`` with ``dtheta_tilde = 2 asin b'`` and update
   the range with the *corrected* sign of ``Delta p`` until ``|dtheta_hat - dtheta_tilde| <
   eps``.  Steps 2-5 repeat while the predicted ``rho, theta`` still move the ellipse by more
   than ``refit_tol_px`` (``max_refits``; one refit is typical, the paper says "not more than 2
   iterations").
   With the Sun direction known, the pixels are then refitted with the physical limb profile
   (section below) and its ellipse replaces the edge fit's in steps 4-6.
6. **Output.**  The observer position ``p`` (Earth centre at ``-p``, camera frame): line of
   sight ``-p/|p|``, range ``|p|``, ``center_rc`` = pinhole projection of the Earth centre
   (not the ellipse centre: they differ by ``gamma_off`` and the perspective offset).  The
   covariance is ``G P_fit G^T`` with ``P_fit`` the fit covariance of ``(r0, c0, a)``
   (:math:`\hat\sigma^2 (J^\top J)^{-1}`) and ``G`` the central-difference Jacobian of steps 4-5.

Physical limb profile (``EarthOptions.profile``, default ``"auto"``)
-------------------------------------------------------------------
The edge models of step 3 put the limb where a blurred step with a smooth interior has its
50 % level.  A lit limb seen from a finite range is brighter in a rim a fraction of a pixel
wide (Lommel-Seeliger ``2\mu_0/(\mu_0 + \mu) \to 2`` as the emission cosine ``\mu \to 0``
while ``\mu_0 > 0``; the view rays converge, the Sun's are parallel), which the ramp's
``\sqrt{u}`` term follows only in part: the fitted edge moves outward by 0.05 px on the
renders of ``benchmarks/navigate_e2e.py`` (range 0.01-0.05 % short), tens of its own
sigmas at 40 000 km, so the position error was inconsistent with the covariance (issue 4:
mean NEES 4-13 instead of 3).  With the Sun direction known, step 3 is followed by a fit of
the *same* pixels with the blurred lunar-Lambert radiance of :mod:`jaxlimb.pipeline.profile`
(:data:`~jaxlimb.pipeline.profile.LIMB_PROFILE`, as the Moon pipeline's
``profile="lunar-lambert"``): free ``(r0, c0, a, sigma, amp, ymin)`` and the lunar-Lambert
weight ``L`` (0: Lambert, 1: Lommel-Seeliger; ``EarthOptions.lunar_lambert_L`` fixes it);
the ellipse shape ``theta, rho`` held at the image of the limb spheroid at the current
position (the same prediction as step 2, repeated after the fit while it moves the ellipse by
more than ``refit_tol_px``; estimated with the free ellipse); the Sun's image direction
(:func:`jaxlimb.imaging.sun_direction_image`) and the phase ``acos(-s . u)`` from
``sun_dir_camera``; ``inv_f = 1/f``.  The profile's geometry is the sphere's
(``\sin e \approx d/R`` along each ray, ``R`` the ellipse radius in the ray's direction):
the flattening (0.34 %) changes the limb's curvature, hence the depth scale of ``\mu``, by
< 1 %, a second-order change of a sub-pixel profile.  The levels ``amp, ymin`` start at their
linear least-squares values for the starting geometry (the edge fit's ``ymax`` is no radiance
scale when its ramp terms carry the interior, e.g. on crescents).  Its ``(r0, c0, a)`` (and
``rho, theta`` when free) then go through steps 4-6 as the edge fit's would, covariance
included.  ``"auto"`` keeps the edge fit (``extras["profile_rejected"]`` says why) when the
fitted ``L`` is outside ``[-0.1, 1.1]`` (photometry not lunar-Lambert-like, e.g. a flat
disc), the fit fails, or it moves the limb by more than half the band from the edge fit
(a sub-pixel correction is expected); it is not used for the paper's flat ESF
(``interior_ramp=False``).  Measured with a known attitude (``benchmarks/navigate_e2e.py
--earth-targets``, 12-bit renders, Lommel-Seeliger, 40 deg phase, 380 000 and 40 000 km):
centre errors 0.003-0.01 px instead of 0.05-0.07 px, range errors below 0.01 % instead of
0.01-0.06 %; ``benchmarks/horizon_vs_sigmoid.py``: more accurate than Christian-Robinson on
the same frames in every Earth row (full / gibbous / crescent, whole and +-30 deg arcs);
``benchmarks/navigate_e2e.py`` (100 runs, 8 bit + 10 DN): mean NEES 3.5 and 3.4 instead of
5.2 and 9.6.  A rendered 100 km glow shell lifts the profile's limb by ~1 km as it does the
edge fit's (range 0.02-0.045 % short with ``atmosphere_km = 0``): the profile still applies.

Free ellipse (``R_body_to_camera`` unknown)
-------------------------------------------
Then the pole is unknown, ``rho`` and ``theta`` are fitted.  Two facts (derived and tested):

* the cone's *major* sine ``a'`` equals ``(Re + h)/|p|`` to 8.5e-5 (relative, 40 000 km, any
  latitude; 1e-6 at 380 000 km): the equatorial diameter perpendicular to the meridian plane is
  always seen whole.  So the range is ``(Re + h)/a'`` with no pole needed.
* the centre offset cannot be signed: the spheroid seen from latitude ``+phi`` with its pole
  tilted toward the top of the image and the mirror configuration produce the *same* limb cone
  (the cone is symmetric about its minor-axis plane), with body centres ``± gamma_off`` apart
  along the minor axis.  The cone axis is returned as the centre direction and the unknown
  offset is added to the covariance as a uniform error ``var = gamma_off^2 / 3`` along the
  minor axis, with ``|phi|`` from the measured ratio (far field:
  ``rho^2 = sin^2 phi + (Rp/Re)^2 cos^2 phi``).  ``gamma_off`` reaches 15 arcsec at 40 000 km
  (0.26 px with the 8 mm camera) and 0.17 arcsec at 380 000 km.

Atmosphere
----------
``atmosphere_km`` (hint) grows both radii (the "limb height above the solid body", DESIGN.md):
the edge model's 50 % level is taken to lie at that height.  It is the *effective* height of
the limb in the image, not the top of the atmosphere: a rendered glow shell 100 km high (scale
height 8 km, brightness 0.3 of the surface) moves the fitted limb up by only 0.3-1.6 km (range
0.004-0.025 % short, ``benchmarks/results/earth_targets.json``, variant ``glow100``), whereas
``atmosphere_km = 100`` would make the range 1.6 % long.  The glow is never taken as the limb.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ..errors import ConfigError, ConvergenceError, GeometryError, LimbInputError, TooManyOutliersError
from ..geometry.camera import Camera
from ..geometry.earth import (
    EARTH_EQUATORIAL_KM,
    EARTH_POLAR_KM,
    earth_range_iteration,
    gamma_off as earth_gamma_off,
)
from ..geometry.ellipsoid import check_rotation, ellipse_to_conic, image_conic
from ..imaging import Hints, front_end as run_front_end, sun_direction_image
from ..models.ellipse_ramp import ELLIPSE_RAMP, EllipseRampParams, ellipse_ramp_intensity
from ..models.lunar_lambert import LIMB_PROFILE, PROFILE_FIXED, LimbProfileParams, limb_profile_intensity, lunar_lambert_weight
from .profile import l_band
from .result import EllipseResult, LimbMeasurement

__all__ = [
    "ELLIPSE_RAMP",
    "EarthCone",
    "EarthOptions",
    "EllipseRampParams",
    "earth_position_from_ellipse",
    "ellipse_ramp_intensity",
    "image_ellipse_cone",
    "locate_earth",
]


# =============================================================================== options
@dataclass(frozen=True)
class EarthOptions:
    """Settings of :func:`locate_earth` (all have working defaults).

    Attributes
    ----------
    front_end
        ``"gradient"`` (default) or ``"scanline"``: the limb-candidate front end.
    band_px
        Half-width (px) of the pixel band about the current ellipse used in the sigmoid fit.
    arc_margin_deg
        Degrees removed from each end of the lit arc (the horns, where the limb meets the
        terminator and the edge fades).
    free_ellipse
        ``None`` (default): fit ``rho`` and ``theta`` only when ``R_body_to_camera`` is unknown;
        ``True`` forces the free ellipse even when it is known (comparison runs).
    max_refits
        Maximum number of fits (step 2-5 passes) with ``rho, theta`` predicted from the
        latest position.
    refit_tol_px
        Stop refitting when the newly predicted ellipse differs from the fitted one's shape
        by less than this (px, at the semi-major axis).
    eps_rad
        Tolerance of the range iteration ``|dtheta_hat - dtheta_tilde|`` (rad).
    max_iter
        Maximum ``Delta p`` updates of the range iteration.
    solver
        A solver object or name (``jaxlimb.fitting.SOLVERS``); ``None`` = default LM.
    k_init
        Initial sigmoid steepness (1/px).
    interior_ramp
        Fit :data:`ELLIPSE_RAMP` (the ESF plus a linear brightness ramp inside the limb, default)
        instead of the paper's flat-topped ESF (``False``); see :func:`ellipse_ramp_intensity`.
    fix_profile
        Names among ``("g", "g2", "h1", "h2", "h3", "h4")`` held at 0 in the edge model
        (ablation studies).
    profile
        ``"auto"`` (default): after the edge fit, refit the same pixels with the physical limb
        profile (:data:`jaxlimb.pipeline.profile.LIMB_PROFILE`) when the hints give the Sun
        direction, keeping the edge fit when the fitted ``L`` is outside ``[-0.1, 1.1]``
        (not lunar-Lambert-like photometry) or the profile fit fails
        (``extras["profile_rejected"]``); ``"sigmoid"``: the edge fit only (step 3);
        ``"lunar-lambert"``: always the profile (needs ``sun_dir_camera``).  See "Physical
        limb profile" in the module docstring.
    lunar_lambert_L
        The lunar-Lambert weight ``L`` of the profile held fixed; ``None`` (default): estimated.
    profile_band_px
        Half-width (px) of the pixel band of the profile fit (about the edge fit's ellipse);
        ``None`` = ``band_px``.
    """

    front_end: str = "gradient"
    band_px: float = 4.0
    arc_margin_deg: float = 30.0
    free_ellipse: bool | None = None
    max_refits: int = 3
    refit_tol_px: float = 2e-3
    eps_rad: float = 1e-13
    max_iter: int = 20
    solver: Any = None
    k_init: float = 1.5
    interior_ramp: bool = True
    fix_profile: tuple[str, ...] = ()
    profile: str = "auto"
    lunar_lambert_L: float | None = None
    profile_band_px: float | None = None

    def __post_init__(self) -> None:
        if self.profile not in ("auto", "sigmoid", "lunar-lambert"):
            raise ConfigError(f"EarthOptions.profile must be 'auto', 'sigmoid' or 'lunar-lambert', got {self.profile!r}")
        if self.lunar_lambert_L is not None and not (isinstance(self.lunar_lambert_L, (int, float))
                                                     and math.isfinite(self.lunar_lambert_L)):
            raise ConfigError(f"EarthOptions.lunar_lambert_L must be a finite number or None, got {self.lunar_lambert_L!r}")
        if self.profile_band_px is not None and not (isinstance(self.profile_band_px, (int, float))
                                                     and math.isfinite(self.profile_band_px) and self.profile_band_px > 1.0):
            raise ConfigError(f"EarthOptions.profile_band_px must be None or a finite number > 1, got {self.profile_band_px!r}")
        if self.front_end not in ("gradient", "scanline"):
            raise ConfigError(f"EarthOptions.front_end must be 'gradient' or 'scanline', got {self.front_end!r}")
        for name, lo in (("band_px", 1.0), ("refit_tol_px", 0.0), ("eps_rad", 0.0), ("k_init", 0.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > lo):
                raise ConfigError(f"EarthOptions.{name} must be a finite number > {lo}, got {v!r}")
        if not (isinstance(self.arc_margin_deg, (int, float)) and 0 <= self.arc_margin_deg < 80):
            raise ConfigError(f"EarthOptions.arc_margin_deg must be in [0, 80) deg, got {self.arc_margin_deg!r}")
        for name in ("max_refits", "max_iter"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
                raise ConfigError(f"EarthOptions.{name} must be an integer >= 1, got {v!r}")


# =============================================================================== cone of an image ellipse
@dataclass(frozen=True)
class EarthCone:
    """The limb cone of a measured image ellipse (camera frame), Eq. (3)-(8).

    Attributes
    ----------
    axis
        Unit cone axis ``v_c`` (camera frame, ``z > 0``): the "ellipse-centre direction".
    semi_axes
        ``(a', b')``, ``a' >= b'``: sines of the cone's half-angles (Eq. 8).
    major_dir, minor_dir
        Unit eigenvectors ``w_1``, ``w_2`` (camera frame) of the major and minor half-angles.
    """

    axis: np.ndarray
    semi_axes: tuple[float, float]
    major_dir: np.ndarray
    minor_dir: np.ndarray


def image_ellipse_cone(camera: Camera, center_rc, semi_axes_px, angle_rad: float) -> EarthCone:
    r"""Lift an image ellipse to its cone of rays and analyse it (Eq. 3-8).

    A pixel ``h = [col, row, 1]`` on the conic ``h^T C h = 0`` (negative inside) has the ray
    ``d = K^{-1} h``, so the rays satisfy ``d^T (K^T C K) d = 0``; ``M_c = -K^T C K`` is positive
    on rays that hit the body, with eigenvalues of signs ``(-, -, +)`` (§III-A).  Sorting the
    negative ones by magnitude, ``a' = (1 + |\lambda_1|/\lambda_3)^{-1/2}``,
    ``b' = (1 + |\lambda_2|/\lambda_3)^{-1/2}`` (Eq. 8 with ``\xi_i = |\lambda_i|^{-1/2}``).

    Raises
    ------
    GeometryError
        Not an ellipse, or an eigen-structure other than ``(-, -, +)``.
    ConfigError
        A camera with lens distortion (the limb is then not a conic in the image).
    """
    if camera.has_distortion:
        raise ConfigError(
            "the Earth pipeline fits the limb as an image ellipse and needs a pinhole camera; "
            f"got distortion (k1, k2, k3, p1, p2) = {camera.distortion}"
        )
    C = ellipse_to_conic(center_rc, semi_axes_px, angle_rad)
    K = camera.K
    M = -(K.T @ C @ K)
    M = 0.5 * (M + M.T)
    lam, V = np.linalg.eigh(M)
    if not (lam[0] < 0 and lam[1] < 0 and lam[2] > 0):
        raise GeometryError(f"image ellipse does not define a limb cone: eigenvalues {lam.tolist()} (need -, -, +)")
    axis = V[:, 2] * (1.0 if V[2, 2] > 0 else -1.0)
    # lam ascending: lam[0] is the most negative (minor half-angle), lam[1] the major one
    a_ = 1.0 / math.sqrt(1.0 + abs(lam[1]) / lam[2])
    b_ = 1.0 / math.sqrt(1.0 + abs(lam[0]) / lam[2])
    return EarthCone(axis=axis, semi_axes=(a_, b_), major_dir=V[:, 1].copy(), minor_dir=V[:, 0].copy())


# =============================================================================== ellipse -> position
def _spheroid(hints: Hints) -> tuple[float, float, float]:
    radii = hints.body_radii_km if hints.body_radii_km is not None else (EARTH_EQUATORIAL_KM, EARTH_EQUATORIAL_KM, EARTH_POLAR_KM)
    a, b, c = (float(v) for v in radii)
    if abs(a - b) > 1e-9 * a:
        raise GeometryError(
            f"the Earth pipeline needs a spheroid with body_radii_km[0] == body_radii_km[1], got {list(radii)}"
        )
    h = float(hints.atmosphere_km or 0.0)
    return a, c, h


def earth_position_from_ellipse(
    camera: Camera,
    center_rc,
    semi_axes_px,
    angle_rad: float,
    p0_camera_km,
    *,
    pole_camera=None,
    equatorial_km: float = EARTH_EQUATORIAL_KM,
    polar_km: float = EARTH_POLAR_KM,
    atmosphere_km: float = 0.0,
    eps_rad: float = 1e-13,
    max_iter: int = 20,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Observer position relative to the Earth centre (camera frame, km) from its image ellipse.

    With ``pole_camera`` (the spin axis in the camera frame, ``R_body_to_camera[:, 2]``): steps 4-5
    of the module docstring (cone, ``gamma_off``, range iteration of Fig. 2 from ``p0_camera_km``).
    Without it: the free-ellipse inversion ``p = -(Re + h)/a' v_c`` (module docstring).

    Returns
    -------
    p, info
        ``p`` (observer - Earth centre, camera frame) and ``{"iterations", "converged",
        "gamma_off_rad", "b_prime", "a_prime", "cone"}``.

    Raises
    ------
    GeometryError
        Bad ellipse, prior inside the Earth, or the iteration did not converge.
    """
    cone = image_ellipse_cone(camera, center_rc, semi_axes_px, angle_rad)
    a_, b_ = cone.semi_axes
    Re = equatorial_km + atmosphere_km
    if pole_camera is None:
        rng = Re / a_
        return -rng * cone.axis, {"iterations": 0, "converged": True, "gamma_off_rad": 0.0, "a_prime": a_, "b_prime": b_, "cone": cone}
    fix = earth_range_iteration(
        cone.axis, b_, p0_camera_km, atmosphere_km=atmosphere_km, pole=pole_camera, eps=eps_rad, max_iter=max_iter,
        equatorial_km=equatorial_km, polar_km=polar_km,
    )
    if not fix.converged:
        raise GeometryError(
            f"Earth range iteration did not reach |dtheta_hat - dtheta_tilde| < {eps_rad:g} rad in {max_iter} updates "
            f"(last {fix.history[-1][1]:.3g} rad)"
        )
    return fix.position_km, {
        "iterations": fix.iterations, "converged": True, "gamma_off_rad": fix.gamma_off_rad,
        "a_prime": a_, "b_prime": b_, "cone": cone,
    }


# =============================================================================== pixel selection
def _band_pixels(shape, ell: tuple, band: float, lit_dir, half_angle: float) -> np.ndarray:
    """Pixels ``(row, col)`` within ``band`` px of the ellipse and inside the lit arc."""
    (r0, c0), (a, b), th = ell
    R = a + band + 2
    rows = np.arange(max(0, int(math.floor(r0 - R))), min(shape[0], int(math.ceil(r0 + R)) + 1))
    cols = np.arange(max(0, int(math.floor(c0 - R))), min(shape[1], int(math.ceil(c0 + R)) + 1))
    if rows.size == 0 or cols.size == 0:
        return np.zeros((0, 2))
    rr, cc = np.meshgrid(rows.astype(float), cols.astype(float), indexing="ij")
    dr, dc = rr - r0, cc - c0
    ct, st = math.cos(th), math.sin(th)
    x = dc * ct - dr * st
    y = -dr * ct - dc * st
    # distance to the ellipse ~ (beta/rho - a) scaled to the local normal: use the
    # first-order distance |F| / |grad F| with F = x^2/a^2 + y^2/b^2 - 1
    F = x * x / (a * a) + y * y / (b * b) - 1.0
    g = 2.0 * np.hypot(x / (a * a), y / (b * b))
    dist = np.abs(F) / np.maximum(g, 1e-300)
    m = dist <= band
    if lit_dir is not None:
        d = np.array(lit_dir, float)
        d /= np.linalg.norm(d)
        nrm = np.hypot(dr, dc)
        cosang = (dr * d[0] + dc * d[1]) / np.maximum(nrm, 1e-300)
        m &= cosang >= math.cos(half_angle)
    return np.column_stack([rr[m], cc[m]])


def _as_hints(hints: Any) -> Hints:
    if hints is None:
        return Hints(body="earth")
    if isinstance(hints, Hints):
        return hints
    if isinstance(hints, dict):
        return Hints.from_dict(hints)
    raise ConfigError(f"`hints` must be a Hints, a dict or None, got {type(hints).__name__}")


def _solver(options: Any):
    from ..fitting import solver_from_name

    s = getattr(options, "solver", None)
    if s is None:
        return None
    if isinstance(s, str):
        return solver_from_name(s)
    return s


# =============================================================================== physical limb profile


def _use_profile(opt: EarthOptions, h: Hints) -> bool:
    """``profile="auto"``: the physical profile when the Sun direction is known and the edge model is
    the default one (the paper's flat ESF, ``interior_ramp=False``, is a sigmoid experiment: kept as
    it is, as the Moon pipeline keeps the papers' fixed-``k`` CSF); ``"lunar-lambert"``: always."""
    if opt.profile == "sigmoid":
        return False
    if h.sun_dir_camera is None:
        if opt.profile == "lunar-lambert":
            raise ConfigError("EarthOptions.profile = 'lunar-lambert' needs the Sun direction (hints `sun_dir_camera`)")
        return False
    return opt.profile == "lunar-lambert" or opt.interior_ramp


def _fit_profile_earth(img, pts, z, edge, fitted, p, camera: Camera, h: Hints, R, radii_limb, opt: EarthOptions,
                       solver, lit_dir, half, geo_kw):
    """Refit the edge fit's pixels with :data:`~jaxlimb.pipeline.profile.LIMB_PROFILE` (module docstring).

    ``edge`` the edge fit's parameters, ``fitted`` its ellipse ``((r0, c0), (a, b), theta)`` and
    ``p`` its position.  Known attitude (``R``): ``theta, rho`` held at the image of the limb
    spheroid at the current position, re-predicted after the fit and the fit repeated (once is
    typical) while they move the ellipse by more than ``refit_tol_px``; free ellipse
    (``R is None``): ``theta, rho`` estimated.  Returns the fit, its ellipse, the position, the
    range-iteration info and the history entries.
    """
    from ..fitting import NormalLM, fit
    from .refine import FitData, _pad_bucket

    band = opt.profile_band_px if opt.profile_band_px is not None else opt.band_px
    if band != opt.band_px:
        pts = _band_pixels(img.shape, fitted, band, lit_dir, half)
        z = img[pts[:, 0].astype(int), pts[:, 1].astype(int)]
    (r0, c0), (a, b), th = fitted
    center = (float(r0), float(c0))
    s = np.asarray(h.sun_dir_camera, dtype=float)
    s = s / np.linalg.norm(s)
    phase = float(np.arccos(np.clip(-s @ camera.los(np.array(center)), -1.0, 1.0)))
    sun_rc = sun_direction_image(s, camera, center)
    if sun_rc is None:
        sun_rc = (1.0, 0.0)  # full or new: the direction does not matter (sin(phase) ~ 0)
    if R is not None:
        ic = image_conic(camera, radii_limb, -p, R)
        rho0, th0 = float(ic.rho), float(ic.angle_rad)
    else:
        rho0, th0 = float(b / a), float(th)
    if isinstance(edge, EllipseRampParams):
        s_tot = 1.0 / max(float(edge.k), 1e-6)  # Gaussian kernel: sigma = 1/k
    else:
        s_tot = 1.7 / max(float(edge.k), 1e-6)  # logistic k -> Gaussian-equivalent sigma (~1.7/k)
    sigma0 = math.sqrt(max(s_tot * s_tot - 1.0 / 12.0, 0.09))
    L0 = lunar_lambert_weight(phase) if opt.lunar_lambert_L is None else float(opt.lunar_lambert_L)
    q = LimbProfileParams(r0=center[0], c0=center[1], a=float(a), theta=th0, rho=rho0, sigma=sigma0, amp=1.0,
                          ymin=0.0, sun_r=sun_rc[0], sun_c=sun_rc[1], phase=phase, inv_f=1.0 / camera.focal_px, L=L0)
    # the levels enter linearly: start them at their least-squares values for this geometry (the
    # edge fit's ymax is no radiance scale when its ramp terms carry the interior)
    F0 = np.asarray(limb_profile_intensity(q, jnp.asarray(np.asarray(pts, float))))
    A = np.column_stack([F0, np.ones_like(F0)])
    (amp0, ymin0), *_ = np.linalg.lstsq(A, np.asarray(z, float), rcond=None)
    if not (math.isfinite(amp0) and amp0 > 0):
        amp0, ymin0 = max(float(np.percentile(z, 95)) - float(edge.ymin), 1e-6), float(edge.ymin)
    q = q.replace(amp=float(amp0), ymin=float(ymin0))
    fixed = tuple(n for n in PROFILE_FIXED if not (n == "L" and opt.lunar_lambert_L is None))
    if R is None:
        fixed = tuple(n for n in fixed if n not in ("theta", "rho"))
    coords, zz, w = _pad_bucket(FitData(np.asarray(pts, float), np.asarray(z, float), None, 0.0, 1.0))
    hist = []
    res = None
    p_cur = p
    for i in range(opt.max_refits):
        if solver is not None:
            s_i = solver
        else:  # tolerance on the parameters' own scale (px, DN), as the Moon pipeline's profile fit
            s_i = NormalLM(rtol=0.0, atol=1e-7) if i == 0 else NormalLM(rtol=0.0, atol=1e-5, coarse_stride=1)
        res = fit(LIMB_PROFILE, coords, zz, q, s_i, fixed=fixed, weights=w, throw=False)
        if not bool(res.converged):
            raise ConvergenceError(f"the lunar-Lambert limb profile fit ({res.solver}) did not converge: {res.message}")
        q = res.params
        vals = np.array([float(getattr(q, n)) for n in LIMB_PROFILE.param_names])
        if not np.all(np.isfinite(vals)):
            raise ConvergenceError(f"the lunar-Lambert limb profile fit returned non-finite parameters {vals.tolist()}")
        if float(q.sigma) < 0:  # the model depends on sigma^2 only
            q = q.replace(sigma=-float(q.sigma))
        a_f, rho_f, th_f = float(q.a), float(q.rho), float(q.theta)
        if a_f <= 0 or rho_f <= 0 or float(q.amp) <= 0:
            raise GeometryError(f"limb profile fit gave a non-physical limb: a = {a_f}, rho = {rho_f}, "
                                f"sigma = {float(q.sigma)}, amp = {float(q.amp)}")
        b_f = rho_f * a_f
        if b_f > a_f:
            a_f, b_f, th_f = b_f, a_f, th_f + math.pi / 2
        pf = ((float(q.r0), float(q.c0)), (a_f, b_f), th_f % math.pi)
        moved = _ell_change(fitted, pf)
        if not moved <= 0.5 * band:  # a sub-pixel correction of the edge fit is expected
            raise GeometryError(f"the limb profile fit moved the limb by {moved:.3g} px from the edge fit "
                                f"(more than half the band, {0.5 * band:g} px)")
        p_cur, info = earth_position_from_ellipse(
            camera, *pf, p_cur, pole_camera=geo_kw["pole"], equatorial_km=geo_kw["equatorial_km"],
            polar_km=geo_kw["polar_km"], atmosphere_km=geo_kw["atmosphere_km"], eps_rad=opt.eps_rad, max_iter=opt.max_iter,
        )
        hist.append({"fit": i + 1, "range_km": float(np.linalg.norm(p_cur)),
                     "range_iterations": info["iterations"], "fit_steps": int(res.n_steps)})
        if R is None:
            break
        icn = image_conic(camera, radii_limb, -p_cur, R)
        new = (pf[0], (float(q.a), float(q.a) * float(icn.rho)), float(icn.angle_rad))
        if _ell_change(pf, new) < opt.refit_tol_px:
            break
        q = q.replace(theta=float(icn.angle_rad), rho=float(icn.rho))
    assert res is not None
    return res, pf, p_cur, info, hist


# =============================================================================== main entry
def locate_earth(image: np.ndarray, camera: Camera, hints: Any = None, options: Any = None) -> LimbMeasurement:
    """Measure the Earth's centre, line of sight and range in an image (module docstring).

    Parameters
    ----------
    image
        2-D grey image ``[row, col]``.
    camera
        :class:`~jaxlimb.geometry.camera.Camera` (required: the range needs it).  With lens
        distortion the frame is resampled onto the ideal pixel grid first
        (:func:`_locate_earth_distorted`).
    hints
        :class:`~jaxlimb.imaging.Hints`, its dict, or ``None``.  Used: ``R_body_to_camera``
        (fixes ``rho, theta``; else the free ellipse), ``range_prior_km`` (start of the loop),
        ``atmosphere_km``, ``body_radii_km`` (spheroid; default WGS-84), ``sun_dir_camera``
        (lit side), ``expected_radius_px``.
    options
        :class:`EarthOptions`; or another options object (e.g. the Moon pipeline's
        ``LocateOptions``) of which only ``front_end`` and ``solver`` are used, the rest being
        the :class:`EarthOptions` defaults; ``None`` = defaults.

    Returns
    -------
    LimbMeasurement
        ``center_rc`` = projection of the Earth centre; ``ellipse`` = the fitted limb ellipse;
        ``los_camera``, ``range_km``; ``covariance`` over ``center_r, center_c, range_km`` (and
        the fit parameters ``a, k, ymax, ymin``, ``rho, theta`` when free); ``extras`` with the
        iteration counts, ``gamma_off``, timings.

    Raises
    ------
    ConfigError
        Missing camera, bad hints or options.
    GeometryError
        Non-spheroidal radii, prior inside the Earth, no convergence of the range iteration.
    CheckFailed
        Front-end checks (no body, too small, outliers, radius inconsistent), too few lit
        pixels, or a sigmoid fit that did not converge.
    """
    from ..fitting import fit
    from ..models import ELLIPSE, EllipseParams

    t0 = time.perf_counter()
    if not isinstance(camera, Camera):
        raise ConfigError(f"`camera` must be a Camera (the Earth range needs it), got {type(camera).__name__}")
    shape = np.shape(image)
    if len(shape) >= 2 and (camera.rows, camera.cols) != tuple(shape[:2]):
        raise ConfigError(f"camera size {camera.rows}x{camera.cols} does not match the image size {shape[0]}x{shape[1]}")
    if camera.has_distortion:
        return _locate_earth_distorted(image, camera, hints, options)
    h = _as_hints(hints)
    if h.body is None:
        h = Hints(**{**h.__dict__, "body": "earth"})
    if isinstance(options, EarthOptions):
        opt = options
    else:  # e.g. the Moon pipeline's LocateOptions: its front-end and profile choices carry over
        fe = getattr(options, "front_end", "gradient")
        prof = getattr(options, "profile", "auto")
        lam = getattr(options, "lunar_lambert_L", None)
        opt = EarthOptions(front_end=fe if fe in ("gradient", "scanline") else "gradient",
                           profile=prof if prof in ("auto", "sigmoid", "lunar-lambert") else "auto",
                           lunar_lambert_L=float(lam) if isinstance(lam, (int, float)) else None)
    Re, Rp, atm = _spheroid(h)
    radii_limb = np.array([Re + atm, Re + atm, Rp + atm])
    R = None if h.R_body_to_camera is None else check_rotation(np.asarray(h.R_body_to_camera), "R_body_to_camera", tol=1e-6)
    free = opt.free_ellipse if opt.free_ellipse is not None else (R is None)
    solver = _solver(options)

    # ---- 1. limb candidates (front end)
    cand = run_front_end(opt.front_end, image, hints=h, camera=camera)
    img = np.asarray(image, dtype=float)
    if img.ndim == 3:
        img = img.mean(axis=2)
    c_rc = np.array(cand.center_rc, float)
    u0 = camera.los(c_rc)
    D0 = h.range_prior_km
    if D0 is None:
        D0 = (Re + atm) / math.sin(math.atan(cand.radius / camera.focal_px))
    if not D0 > Re + atm:
        raise GeometryError(f"range prior {D0:.6g} km puts the observer inside the Earth (radius {Re + atm:.6g} km)")
    p = -D0 * u0  # observer relative to the Earth centre, camera frame
    # lit arc
    lit_dir, half = cand.lit_direction, cand.lit_halfangle
    if h.sun_dir_camera is not None:
        sd = sun_direction_image(h.sun_dir_camera, camera, tuple(c_rc))
        if sd is not None:
            lit_dir, half = sd, math.pi / 2
    if lit_dir is not None:
        half = min(half, math.pi / 2) - math.radians(opt.arc_margin_deg)
        if half <= math.radians(5):
            raise TooManyOutliersError(f"lit arc too short for the Earth fit: half-angle {math.degrees(half):.1f} deg")

    # ---- initial ellipse: predicted shape (known attitude) or a circle
    if R is not None:
        ic = image_conic(camera, radii_limb, -p, R)
        rho_p, th_p = ic.rho, ic.angle_rad
    else:
        rho_p, th_p = 0.999, 0.0
    a_init = cand.radius / math.sqrt(rho_p)
    ell = ((float(c_rc[0]), float(c_rc[1])), (a_init, a_init * rho_p), th_p)
    fixed = (() if free else ("rho", "theta")) + (tuple(opt.fix_profile) if opt.interior_ramp else ())
    prev = None
    res = None
    history = []
    k_cur, ymax_cur, ymin_cur, g_cur, g2_cur = opt.k_init, None, None, 0.0, 0.0
    hs = [0.0, 0.0, 0.0, 0.0]
    t_fit = 0.0
    for it in range(opt.max_refits):
        pts = _band_pixels(img.shape, ell, opt.band_px, lit_dir, half if lit_dir is not None else math.pi)
        if pts.shape[0] < 50:
            raise TooManyOutliersError(f"only {pts.shape[0]} pixels in the lit limb band (need >= 50)")
        z = img[pts[:, 0].astype(int), pts[:, 1].astype(int)]
        if ymax_cur is None:
            (r0_, c0_), (a0_, b0_), th_ = ell
            F = _band_signed(pts, ell)
            inner, outer = z[F < -0.5 * opt.band_px], z[F > 0.5 * opt.band_px]
            ymax_cur = float(np.median(inner)) if inner.size else float(np.percentile(z, 90))
            ymin_cur = float(np.median(outer)) if outer.size else float(np.percentile(z, 10))
        (r0_, c0_), (a0_, b0_), th_ = ell
        pkw = dict(r0=r0_, c0=c0_, a=a0_, theta=th_, rho=b0_ / a0_, k=k_cur, ymax=ymax_cur, ymin=ymin_cur)
        init = EllipseRampParams(**pkw, g=g_cur, g2=g2_cur, h1=hs[0], h2=hs[1], h3=hs[2], h4=hs[3]) if opt.interior_ramp else EllipseParams(**pkw)
        tf = time.perf_counter()
        res = fit(ELLIPSE_RAMP if opt.interior_ramp else ELLIPSE, pts, z, init, solver, fixed=fixed, throw=True)
        t_fit += time.perf_counter() - tf
        P = res.params
        a_f, rho_f, th_f = float(P.a), float(P.rho), float(P.theta)
        if a_f <= 0 or rho_f <= 0:
            raise GeometryError(f"elliptical sigmoid fit gave a non-physical ellipse: a = {a_f}, rho = {rho_f}")
        k_cur, ymax_cur, ymin_cur = float(P.k), float(P.ymax), float(P.ymin)
        g_cur = float(P.g) if opt.interior_ramp else 0.0
        g2_cur = float(P.g2) if opt.interior_ramp else 0.0
        hs = [float(getattr(P, n)) for n in ("h1", "h2", "h3", "h4")] if opt.interior_ramp else hs
        b_f = rho_f * a_f
        if b_f > a_f:  # free fit may swap the axes: keep a >= b, theta along a
            a_f, b_f, th_f = b_f, a_f, th_f + math.pi / 2
        th_f = th_f % math.pi
        fitted = ((float(P.r0), float(P.c0)), (a_f, b_f), th_f)
        pole = None if (free or R is None) else R[:, 2]
        p, info = earth_position_from_ellipse(
            camera, *fitted, p, pole_camera=pole, equatorial_km=Re, polar_km=Rp, atmosphere_km=atm,
            eps_rad=opt.eps_rad, max_iter=opt.max_iter,
        )
        history.append({"fit": it + 1, "range_km": float(np.linalg.norm(p)), "range_iterations": info["iterations"],
                        "fit_steps": int(res.n_steps)})
        if free:
            ell = fitted
            if prev is not None and _ell_change(prev, fitted) < opt.refit_tol_px:
                break
            prev = fitted
            continue
        # shape predicted at the new position; refit only if it moves the ellipse noticeably
        icn = image_conic(camera, radii_limb, -p, R)
        new = (fitted[0], (a_f, a_f * icn.rho), icn.angle_rad)
        change = _ell_change(fitted, new)
        ell = new
        if change < opt.refit_tol_px:
            break
        prev = fitted

    assert res is not None
    # ---- 3b. physical limb profile on the same pixels (module docstring, "Physical limb profile")
    esf_summary = None
    profile_rejected = None
    prof_hist: list[dict[str, Any]] = []
    t_prof = time.perf_counter()
    if _use_profile(opt, h):
        geo_kw = dict(pole=None if (free or R is None) else R[:, 2], equatorial_km=Re, polar_km=Rp, atmosphere_km=atm)
        try:
            pres, pfitted, pp_, pinfo, phist = _fit_profile_earth(
                img, pts, z, res.params, fitted, p, camera, h, R if not free else None, radii_limb, opt, solver,
                lit_dir, half if lit_dir is not None else math.pi, geo_kw,
            )
        except (ConvergenceError, GeometryError, LimbInputError) as e:
            if opt.profile != "auto":
                raise
            profile_rejected = {"model": "lunar-lambert", "reason": f"{type(e).__name__}: {e}"}
        else:
            L_fit = float(pres.params.L)
            band_L = l_band(pres)
            if opt.profile == "auto" and not band_L[0] <= L_fit <= band_L[1]:
                # the limb is not lunar-Lambert-like (e.g. a flat disc): keep the edge fit, say why
                profile_rejected = {"model": "lunar-lambert", "L": L_fit, "allowed_L": list(band_L)}
            else:
                esf_summary = {"ellipse_center_rc": list(fitted[0]), "semi_axes_px": list(fitted[1]),
                               "range_km": float(np.linalg.norm(p)), "center_rc": [float(v) for v in camera.project(-p)]}
                res, fitted, p, info = pres, pfitted, pp_, pinfo
                prof_hist = phist
    t_prof = time.perf_counter() - t_prof
    # ---- covariance: (r0, c0, a[, rho, theta]) -> (center_r, center_c, range)
    free_names = list(res.free)
    geo = ["r0", "c0", "a"] + (["rho", "theta"] if free else [])
    idx = [free_names.index(n) for n in geo]
    Pfit = np.asarray(res.covariance)[np.ix_(idx, idx)]
    pole = None if (free or R is None) else R[:, 2]
    Pm = res.params

    def g(x: np.ndarray) -> np.ndarray:
        r0, c0, a = x[:3]
        rho = x[3] if free else float(Pm.rho)
        th = x[4] if free else float(Pm.theta)
        a2, b2, th2 = (a, rho * a, th) if rho <= 1 else (rho * a, a, th + math.pi / 2)
        pp, _ = earth_position_from_ellipse(
            camera, (r0, c0), (a2, b2), th2, p, pole_camera=pole, equatorial_km=Re, polar_km=Rp,
            atmosphere_km=atm, eps_rad=opt.eps_rad, max_iter=opt.max_iter,
        )
        rc = camera.project(-pp)
        return np.array([rc[0], rc[1], np.linalg.norm(pp)])

    x0 = np.array([float(Pm.r0), float(Pm.c0), float(Pm.a)] + ([float(Pm.rho), float(Pm.theta)] if free else []))
    steps = [1e-3, 1e-3, 1e-3] + ([1e-5, 1e-4] if free else [])
    G = np.empty((3, len(x0)))
    for i, hstep in enumerate(steps):
        xp, xm = x0.copy(), x0.copy()
        xp[i] += hstep
        xm[i] -= hstep
        G[:, i] = (g(xp) - g(xm)) / (2 * hstep)
    Pout = G @ Pfit @ G.T
    rng_km = float(np.linalg.norm(p))
    los = -p / rng_km
    center = camera.project(-p)
    goff_model = 0.0
    if free:
        # unknown sign of gamma_off: uniform error +-gamma along the image minor axis
        rho_c = fitted[1][1] / fitted[1][0]
        e2 = (Rp / Re) ** 2
        cos2 = float(np.clip((1 - rho_c**2) / (1 - e2), 0.0, 1.0))
        lat = math.acos(math.sqrt(cos2))
        pe = rng_km * np.array([math.cos(lat), 0.0, math.sin(lat)])
        goff_model = abs(earth_gamma_off(pe, atm, equatorial_km=Re, polar_km=Rp))
        s_px = goff_model * camera.focal_px
        thm = fitted[2] + math.pi / 2
        dmin = np.array([-math.sin(thm), math.cos(thm)])
        Pout[:2, :2] += (s_px**2 / 3.0) * np.outer(dmin, dmin)
    Pout = 0.5 * (Pout + Pout.T)
    names = ["center_r", "center_c", "range_km"]
    cov: dict[str, dict[str, float]] = {a: {b: float(Pout[i, j]) for j, b in enumerate(names)} for i, a in enumerate(names)}
    cf = res.covariance_dict()
    for n in free_names:
        cov.setdefault(n, {})
        for m in free_names:
            cov[n][m] = cf[n][m]
    a_f, b_f = fitted[1]
    is_prof = isinstance(Pm, LimbProfileParams)
    if is_prof:
        s_e = math.sqrt(float(Pm.sigma) ** 2 + 1.0 / 12.0)
        k_out, ymax_out, ymin_out = 1.0 / s_e, float(Pm.ymin) + float(Pm.amp), float(Pm.ymin)
    else:
        k_out, ymax_out, ymin_out = float(Pm.k), float(Pm.ymax), float(Pm.ymin)
    extras = {
        "model": "lunar_limb" if is_prof else ("ellipse_ramp" if opt.interior_ramp else "ellipse"),
        "g": float(Pm.g) if (opt.interior_ramp and not is_prof) else 0.0,
        "free_ellipse": bool(free),
        "rho": b_f / a_f,
        "theta_rad": fitted[2],
        "ellipse_center_rc": list(fitted[0]),
        "gamma_off_rad": float(info["gamma_off_rad"]),
        "gamma_off_unsigned_model_rad": goff_model,
        "a_prime": info["a_prime"],
        "b_prime": info["b_prime"],
        "atmosphere_km": atm,
        "fits": history,
        "range_prior_km": float(D0),
        "initial_circle": {"center_rc": list(cand.center_rc), "radius": cand.radius, "n_points": cand.n_points},
        "residual_rms": float(res.rms),
        "timings_s": {"fit": t_fit, "profile": t_prof, "total": time.perf_counter() - t0},
    }
    if is_prof:
        extras["profile"] = {"model": "lunar-lambert", "psf_sigma_px": abs(float(Pm.sigma)), "amp": float(Pm.amp),
                             "phase_deg": math.degrees(float(Pm.phase)), "L": float(Pm.L),
                             "L_estimated": opt.lunar_lambert_L is None, "fits": prof_hist, "edge_fit": esf_summary}
    if profile_rejected is not None:
        extras["profile_rejected"] = profile_rejected
    return LimbMeasurement(
        center_rc=(float(center[0]), float(center[1])),
        radius_px=None,
        ellipse=EllipseResult(center_rc=fitted[0], semi_axes_px=(float(a_f), float(b_f)), angle_rad=float(fitted[2])),
        k=k_out,
        ymax=ymax_out,
        ymin=ymin_out,
        covariance=cov,
        iterations=int(sum(hh["fit_steps"] for hh in history + prof_hist)),
        solver=res.solver,
        front_end=cand.front_end,
        n_pixels=int(res.n_pixels),
        los_camera=(float(los[0]), float(los[1]), float(los[2])),
        range_km=rng_km,
        extras=extras,
    )


def _locate_earth_distorted(image: np.ndarray, camera: Camera, hints: Any, options: Any) -> LimbMeasurement:
    """:func:`locate_earth` for a lens-distorted camera: measured in the ideal image
    (:func:`jaxlimb.imaging.undistort.undistort_image`), then ``center_rc`` (and its covariance,
    through the distortion's Jacobian) mapped back to the observed image; ``ellipse`` and the
    fit parameters' covariance stay in ideal pixels (``extras["ellipse_frame"]``); LOS and range
    are unchanged."""
    from dataclasses import replace

    from ..imaging.undistort import pinhole_of, undistort_image

    pin = pinhole_of(camera)
    m = locate_earth(undistort_image(image, camera), pin, hints, options)
    c_id = np.asarray(m.center_rc, float)
    h = 1e-3
    Jd = np.empty((2, 2))
    for i in range(2):
        e = np.zeros(2)
        e[i] = h
        Jd[:, i] = (camera.distort(c_id + e) - camera.distort(c_id - e)) / (2 * h)
    # the measurement block (center_r, center_c, range_km) moves with the distortion's Jacobian;
    # the fit parameters' block stays in ideal pixels
    block = list(m.covariance["center_r"])
    P = np.array([[m.covariance[a][b] for b in block] for a in block])
    T = np.eye(len(block))
    idx = [block.index("center_r"), block.index("center_c")]
    T[np.ix_(idx, idx)] = Jd
    P = T @ P @ T.T
    cov = {a: dict(row) for a, row in m.covariance.items()}
    for i, a in enumerate(block):
        cov[a] = {b: float(P[i, j]) for j, b in enumerate(block)}
    c_obs = camera.distort(c_id)
    pix = None if m.selected_pixels_rc is None else camera.distort(np.asarray(m.selected_pixels_rc, float))
    extras = {**m.extras, "ellipse_frame": "ideal (undistorted) pixels", "undistorted_image": True}
    return replace(m, center_rc=(float(c_obs[0]), float(c_obs[1])), covariance=cov, selected_pixels_rc=pix,
                   extras=extras)


def _band_signed(pts: np.ndarray, ell: tuple) -> np.ndarray:
    """Signed first-order distance (px) of pixels to the ellipse (negative inside)."""
    (r0, c0), (a, b), th = ell
    dr, dc = pts[:, 0] - r0, pts[:, 1] - c0
    ct, st = math.cos(th), math.sin(th)
    x = dc * ct - dr * st
    y = -dr * ct - dc * st
    F = x * x / (a * a) + y * y / (b * b) - 1.0
    g = 2.0 * np.hypot(x / (a * a), y / (b * b))
    return F / np.maximum(g, 1e-300)


def _ell_change(e1: tuple, e2: tuple) -> float:
    """Largest displacement (px) between two ellipses, sampled at 64 points."""
    from ..geometry.ellipsoid import ellipse_points

    phi = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    # compare the two curves by the distance of e1's points to e2 (first order)
    p1 = ellipse_points(e1[0], e1[1], e1[2], phi)
    return float(np.max(np.abs(_band_signed(p1, e2))))
