r"""The Earth (any spheroid): elliptical-sigmoid limb fit, centre offset and range iteration (§IV, Fig. 2).

Mortari, D'Souza & Zanetti, "Image Processing of Illuminated Ellipsoid" (J. Spacecraft and
Rockets 53(3), 2016, doi:10.2514/1.A33342), §III-IV and §V-C; the flowchart of Fig. 1 with the
Earth branch of step 5 and the position loop of Fig. 2.

Steps of the ellipsoid strategy of :func:`jaxlimb.pipeline.locate` (:mod:`jaxlimb.pipeline.ellipsoid`)
-------------------------------------------------------------------------------------------------
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

Physical limb profile (``LocateOptions.profile``, default ``"auto"``)
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
weight ``L`` (0: Lambert, 1: Lommel-Seeliger; ``LocateOptions.lunar_lambert_L`` fixes it);
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
* far away the offset vanishes but the free shape costs the centre its precision: on a gibbous arc the fitted
  flattening is nearly collinear with the centre, and the centre's noise-only Cramér-Rao bound without the pole is
  ~10x the attitude-known one (per axis at 380 000 km with the 16 mm camera, 10-90 % 0.03-0.13 px against 0.004-0.013 px;
  ``benchmarks/earth_attitude_floor.py``, which also gives the median error an unbiased estimator reaching that bound
  and the mirror floor would have on the same frames).
* with the Sun direction known and ``EllipsoidOptions.sun_declination_max_deg`` set (the Earth: 23.44 deg), the
  centre is instead marginalised over the poles whose equator the Sun does not leave by more than that
  (:mod:`jaxlimb.pipeline.pole_prior`): the bound often excludes one of the two mirror poles.

Atmosphere
----------
``atmosphere_km`` (hint) grows both radii (the "limb height above the solid body", DESIGN.md):
the edge model's 50 % level is taken to lie at that height.  It is the *effective* height of
the limb in the image, not the top of the atmosphere: a rendered glow shell 100 km high (scale
height 8 km, brightness 0.3 of the surface) moves the fitted limb up by only 0.3-1.6 km (range
0.004-0.025 % short, ``benchmarks/results/earth_targets.json``, variant ``glow100``), whereas
``atmosphere_km = 100`` would make the range 1.6 % long.  The glow is never taken as the limb: the
pixels fitted are the band of ``band_px`` about the predicted limb ellipse on the lit arc (the
limb-pixel stage, :meth:`jaxlimb.pipeline.ellipsoid.Ellipsoid.limb_pixels` and
:func:`_band_pixels`), and the edge model puts the limb at the 50 % point of the bright-to-dark
transition, below a faint glow.

Choosing ``atmosphere_km`` for a real frame: the altitude of the edge you measure -- ``0`` for a
clear limb over ocean or land, the cloud-top height where clouds make the limb (~2 km low stratus,
5-8 km mid-level, 10-12 km tropical cirrus and anvils), for a haze-resolving imager the altitude
where the haze has fallen to half the disc's edge brightness (calibrate once on frames of known
range).  A 1 km error biases the range by 1/6378 (0.016 %), not the line of sight (README).

A glow thinner than a pixel (a 16 km haze beyond ~400 000 km with a 16 mm lens) cannot be told from the
edge: its light lifts the fitted limb by about its brightness times its scale height (0.1 x 16 km = 1.6 km,
0.025 % of the range).  The covariance carries it as a consider parameter
(``EllipsoidOptions.unresolved_glow``, :func:`jaxlimb.pipeline.ellipsoid_profile.with_unresolved_glow`); the
estimate is not moved, since the glow of a given frame is unknown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError, ConvergenceError, GeometryError
from ..geometry.camera import Camera
from ..geometry.earth import (
    EARTH_EQUATORIAL_KM,
    EARTH_POLAR_KM,
    earth_range_iteration,
    gamma_off as earth_gamma_off,
)
from ..geometry.ellipsoid import ellipse_to_conic
from ..imaging import Hints
from ..models.ellipse_ramp import ELLIPSE_RAMP, EllipseRampParams, ellipse_ramp_intensity  # noqa: F401 (re-exported)

__all__ = [
    "ELLIPSE_RAMP",
    "EarthCone",
    "cone_eigen",
    "EllipseRampParams",
    "EllipsoidOptions",
    "earth_position_from_ellipse",
    "ellipse_ramp_intensity",
    "image_ellipse_cone",
    "unsigned_offset_cov",
]


# =============================================================================== options
@dataclass(frozen=True)
class EllipsoidOptions:
    """Settings of the ellipsoid strategy of :func:`jaxlimb.pipeline.locate` (``LocateOptions.ellipsoid``; all
    have working defaults).  The front end, solver, profile and ``lunar_lambert_L`` are
    :class:`~jaxlimb.pipeline.LocateOptions`' own, as for every body.

    Attributes
    ----------
    band_px
        Half-width (px) of the pixel band about the current ellipse used in the edge fit.
    arc_margin_deg
        Degrees removed from each end of the lit arc (the horns, where the limb meets the
        terminator and the edge fades).
    free_ellipse
        ``None`` (default): fit ``rho`` and ``theta`` only when ``R_body_to_camera`` is unknown (or
        ``LocateOptions.model = "ellipse"``); ``True`` forces the free ellipse (comparison runs).
    max_refits
        Maximum number of fits (step 2-5 passes) with ``rho, theta`` predicted from the
        latest position.
    refit_tol_px
        Stop refitting when the newly predicted ellipse differs from the fitted one's shape
        by less than this (px, at the semi-major axis).
    eps_rad
        Tolerance of the range iteration ``|dtheta_hat - dtheta_tilde|`` (rad).
    max_iter
        Maximum ``Delta p`` updates of the range iteration (no convergence: a failed check, exit 3).
    k_init
        Initial steepness (1/px) of the edge model.
    interior_ramp
        Fit :data:`~jaxlimb.models.ELLIPSE_RAMP` (the ESF plus a brightness ramp inside the limb, default)
        instead of the paper's flat-topped ESF (``False``); see :func:`~jaxlimb.models.ellipse_ramp_intensity`.
    fix_profile
        Names among ``("g", "g2", "h1", "h2", "h3", "h4")`` held at 0 in the edge model
        (ablation studies).
    profile_band_px
        Half-width (px) of the pixel band of the profile fit (about the edge fit's ellipse);
        ``None`` = ``band_px``.
    trace
        Start from the limb traced against the sky (:mod:`jaxlimb.pipeline.limb_trace`: the outermost edge along
        rays, per-ray inside levels normalising the band, rays with a cloud edge inside the band left out)
        instead of the front end's circle and one inside level (``False``; the cloudy Earth fails then).
    center_floor_px
        Smallest 1-sigma (px) of the ellipse centre in any direction: the limb model's specification error, which no
        residual shows.  On :mod:`jaxlimb.render.independent`'s uniform-albedo Earths (``benchmarks/families.py``,
        40 000 km, 600 px) the centre is 0.005-0.025 px off for noise sigmas of 0.001-0.007 px (``own`` and ``lambert``
        NEES 3.0 and 3.8 on seed 2026, 6.9 and 22.6 on three held-out frames of seed 2027).  ``0`` keeps the noise
        and model-error terms alone.
    patchy_shading_L
        The lunar-Lambert ``L`` of the shading under an albedo-patchy limb's traced rays (attitude and Sun known):
        each ray's half-level crossing is moved by where it lies on a uniform disc of that shading, blurred by the
        PSF sigma the rays' profiles fit best (:func:`~jaxlimb.pipeline.limb_trace.shading_offsets`,
        :func:`~jaxlimb.pipeline.limb_trace.shading_sigma`).  ``0``: Lambert (the Earth's clouds and surface; not
        measurable from the rays, which the flatness test selects).  ``None``: no correction (the crossings as
        traced: biased toward the Sun by 0.15-0.37 px on Lambert discs).
    sun_declination_max_deg
        Attitude unknown, Sun direction known: the largest angle (deg) between the Sun and the body's equator (the
        Earth: its obliquity, 23.44).  The centre is then marginalised over the poles that bound allows
        (:mod:`jaxlimb.pipeline.pole_prior`), which often decides the sign of the centre offset the limb alone leaves
        open.  ``None`` (default): no bound (the cone axis and the unsigned offset as a uniform error).  Not for scenes
        whose Sun is placed freely (a renderer's): the bound is a fact about the real Sun.
    unresolved_glow
        ``(g_max, H_lo_km, H_hi_km)``: the glow above the measured edge that the covariance carries when the profile
        fit has none (:func:`~jaxlimb.pipeline.ellipsoid_profile.with_unresolved_glow`): its brightness uniform up to
        ``g_max`` (units of the disc's radiance scale ``amp``; or, where the data would see a fainter glow, the
        largest the glow gate misses), its scale height uniform on ``[H_lo_km, H_hi_km]``.  Default ``(0.4, 6.0, 25.0)``: the glows of
        :mod:`jaxlimb.render.independent` (0.03-0.4 of the surface, 6-25 km; the Earth's haze at its limb); ``None``
        for a body without an atmosphere.
    """

    band_px: float = 4.0
    arc_margin_deg: float = 30.0
    free_ellipse: bool | None = None
    max_refits: int = 3
    refit_tol_px: float = 2e-3
    eps_rad: float = 1e-13
    max_iter: int = 20
    k_init: float = 1.5
    interior_ramp: bool = True
    fix_profile: tuple[str, ...] = ()
    profile_band_px: float | None = None
    trace: bool = True
    center_floor_px: float = 0.0075
    patchy_shading_L: float | None = 0.0
    sun_declination_max_deg: float | None = None
    unresolved_glow: tuple[float, float, float] | None = (0.4, 6.0, 25.0)

    def __post_init__(self) -> None:
        if self.profile_band_px is not None and not (isinstance(self.profile_band_px, (int, float))
                                                     and math.isfinite(self.profile_band_px) and self.profile_band_px > 1.0):
            raise ConfigError(f"EllipsoidOptions.profile_band_px must be None or a finite number > 1, got {self.profile_band_px!r}")
        for name, lo in (("band_px", 1.0), ("refit_tol_px", 0.0), ("eps_rad", 0.0), ("k_init", 0.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > lo):
                raise ConfigError(f"EllipsoidOptions.{name} must be a finite number > {lo}, got {v!r}")
        if not (isinstance(self.center_floor_px, (int, float)) and math.isfinite(self.center_floor_px)
                and 0.0 <= self.center_floor_px <= 1.0):
            raise ConfigError(f"EllipsoidOptions.center_floor_px must be in [0, 1] px, got {self.center_floor_px!r}")
        if self.patchy_shading_L is not None and not (isinstance(self.patchy_shading_L, (int, float))
                                                      and 0.0 <= self.patchy_shading_L <= 1.0):
            raise ConfigError(f"EllipsoidOptions.patchy_shading_L must be None or in [0, 1], got {self.patchy_shading_L!r}")
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
        for name in ("max_refits", "max_iter"):
            v = getattr(self, name)
            if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
                raise ConfigError(f"EllipsoidOptions.{name} must be an integer >= 1, got {v!r}")
        bad = set(self.fix_profile) - {"g", "g2", "h1", "h2", "h3", "h4"}
        if bad:
            raise ConfigError(f"EllipsoidOptions.fix_profile names unknown ramp terms {sorted(bad)}")


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
    lam, axis, a_, b_, V = cone_eigen(-(K.T @ C @ K))
    if not (lam[0] < 0 and lam[1] < 0 and lam[2] > 0):
        raise GeometryError(f"image ellipse does not define a limb cone: eigenvalues {lam.tolist()} (need -, -, +)")
    return EarthCone(axis=axis, semi_axes=(float(a_), float(b_)), major_dir=V[:, 1].copy(), minor_dir=V[:, 0].copy())


def cone_eigen(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eigen-analysis (Eq. 8) of limb cones ``M`` ``(..., 3, 3)``, positive on the rays that hit the body: the
    ascending eigenvalues, the unit axis (``z > 0``), the sines ``a' >= b'`` of the half-angles and the eigenvectors
    (columns; ``[..., :, 1]`` the major direction, ``[..., :, 0]`` the minor one).  Signs are not checked."""
    lam, V = np.linalg.eigh(0.5 * (M + np.swapaxes(M, -1, -2)))
    axis = V[..., :, 2] * np.where(V[..., 2, 2] > 0, 1.0, -1.0)[..., None]
    # lam ascending: lam[0] is the most negative (minor half-angle), lam[1] the major one
    with np.errstate(invalid="ignore", divide="ignore"):  # not a cone (lam[2] <= 0): NaN, refused by the callers
        a_ = 1.0 / np.sqrt(1.0 + np.abs(lam[..., 1]) / lam[..., 2])
        b_ = 1.0 / np.sqrt(1.0 + np.abs(lam[..., 0]) / lam[..., 2])
    return lam, axis, a_, b_, V


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
        raise ConvergenceError(
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
    m = np.abs(_band_signed(np.stack([rr, cc], axis=-1), ell)) <= band
    if lit_dir is not None:
        d = np.array(lit_dir, float)
        d /= np.linalg.norm(d)
        nrm = np.hypot(dr, dc)
        cosang = (dr * d[0] + dc * d[1]) / np.maximum(nrm, 1e-300)
        m &= cosang >= math.cos(half_angle)
    return np.column_stack([rr[m], cc[m]])


def _band_signed(pts: np.ndarray, ell: tuple) -> np.ndarray:
    """Signed first-order distance (px) of pixels ``(..., 2)`` to the ellipse (negative inside):
    ``F / |grad F|`` with ``F = x^2/a^2 + y^2/b^2 - 1`` in the ellipse frame of
    :func:`jaxlimb.models.ellipse_coords` (Eq. 19), computed in float64 NumPy: the JAX transform runs in float32,
    whose 1e-4 px resolution at a 2000 px centre swallowed the finite-difference steps of the fits that call this
    (``limb_trace.fit_traced``'s centre never moved from its start)."""
    (r0, c0), (a, b), th = ell
    p = np.asarray(pts, float)
    dr, dc = p[..., 0] - float(r0), p[..., 1] - float(c0)
    ct, st = math.cos(float(th)), math.sin(float(th))
    x, y = dc * ct - dr * st, -dr * ct - dc * st
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


def max_gamma_off(range_km: float, equatorial_km: float, polar_km: float, atmosphere_km: float) -> float:
    """The largest unsigned offset ``|gamma_off|`` (rad, :func:`earth_gamma_off`) over the observer's latitude
    0-90 deg at ``range_km`` (2 deg grid; ~0.3 px at 40 000 km with an 8 mm / 2.2 um imager, 0.007 px at
    385 000 km with 16 mm)."""
    lats = np.radians(np.arange(0.0, 90.1, 2.0))
    return max(abs(earth_gamma_off(range_km * np.array([math.cos(t), 0.0, math.sin(t)]), atmosphere_km,
                                   equatorial_km=equatorial_km, polar_km=polar_km)) for t in lats)


def unsigned_offset_cov(camera: Camera, fitted: tuple, range_km: float, equatorial_km: float, polar_km: float,
                        atmosphere_km: float, n_out: int) -> tuple[np.ndarray, float]:
    """The free ellipse's unsigned centre offset as a model error (module docstring, "Free ellipse"):
    a uniform error ``+-gamma_off`` along the image of the polar axis, ``var = gamma_off^2 / 3`` px^2, in every
    direction (the fitted ellipse's minor axis is no measure of that axis: ``a - b`` is ~0.3 % of ``a``), with
    ``gamma_off`` its largest value over the observer's latitude (:func:`max_gamma_off`).  (The latitude from
    the measured axis ratio was tried: on a lit arc the ratio is not measured well enough, it came out ~1,
    i.e. pole-on and no offset, for frames at 22-44 deg whose centres were 0.1-0.32 px off: centre NEES
    45-760 on ``benchmarks/families.py``'s ``earth_noR`` rows.)  Returns the ``(n_out, n_out)`` covariance (on the
    ``center_r, center_c`` block) and ``gamma_off`` (rad)."""
    del fitted  # the bound does not depend on the fitted shape (docstring)
    goff = max_gamma_off(range_km, equatorial_km, polar_km, atmosphere_km)
    s_px = goff * camera.focal_px
    out = np.zeros((n_out, n_out))
    out[:2, :2] = (s_px**2 / 3.0) * np.eye(2)
    return out, goff
