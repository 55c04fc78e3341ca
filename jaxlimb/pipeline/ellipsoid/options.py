"""Settings of the ellipsoid strategy (:class:`EllipsoidOptions`, ``LocateOptions.ellipsoid``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import ConfigError

__all__ = ["EllipsoidOptions"]


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
        Start from the limb traced against the sky (:mod:`jaxlimb.pipeline.ellipsoid.trace`: the outermost edge along
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
        PSF sigma the rays' profiles fit best (:func:`~jaxlimb.pipeline.ellipsoid.trace.shading_offsets`,
        :func:`~jaxlimb.pipeline.ellipsoid.trace.shading_sigma`).  ``0``: Lambert (the Earth's clouds and surface; not
        measurable from the rays, which the flatness test selects).  ``None``: no correction (the crossings as
        traced: biased toward the Sun by 0.15-0.37 px on Lambert discs).
    sun_declination_max_deg
        Attitude unknown, Sun direction known: the largest angle (deg) between the Sun and the body's equator (the
        Earth: its obliquity, 23.44).  The centre is then marginalised over the poles that bound allows
        (:mod:`jaxlimb.pipeline.ellipsoid.pole_prior`), which often decides the sign of the centre offset the limb alone leaves
        open.  ``None`` (default): no bound (the cone axis and the unsigned offset as a uniform error).  Not for scenes
        whose Sun is placed freely (a renderer's): the bound is a fact about the real Sun.
    unresolved_glow
        ``(g_max, H_lo_km, H_hi_km)``: the glow above the measured edge that the covariance carries when the profile
        fit has none (:func:`~jaxlimb.pipeline.ellipsoid.profile.with_unresolved_glow`): its brightness uniform up to
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


