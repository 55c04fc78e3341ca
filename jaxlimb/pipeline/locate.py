r"""``locate``: image -> image of the body centre, apparent radius, line of sight and range.

The data flow of DESIGN.md, composed from the other packages:

1. validate the image (:func:`jaxlimb.imaging.validate_image`; a constant frame is not an
   input error but "no body", Check 1);
2. the prior (Aerospace 2015 §3) from camera + hints, or measured on the image when they
   give no radius -- any image size -- and the front end (``gradient`` default, or
   ``scanline``), which raise Checks 1-4 (:mod:`jaxlimb.pipeline.checks`);
3. refinement (:mod:`jaxlimb.pipeline.refine`): annulus on the lit side, circular sigmoid
   with ``k`` estimated (or ``k = 3`` and fixed levels), outlier pass; Checks 3, 5 (no
   convergence, jump from the Taubin circle), 1 and 4 on the refined circle;
4. body-centre correction (camera known): the limb of a sphere off the optical axis is an
   ellipse whose centre is not the image of the body centre (~1 px apart at the corners of
   the default imager).  The elliptical sigmoid is refitted with the axis ratio and
   orientation of the image of a sphere at the estimated place, and the fitted ellipse
   centre and radial semi-axis are mapped *exactly* to the body-centre image, its line of
   sight and the angular radius (:mod:`jaxlimb.pipeline.sphere`; equivalent to
   :func:`jaxlimb.geometry.navigation.sphere_from_ellipse`).  ``radius_px`` is then the
   on-axis-equivalent radius ``f tan(alpha) = b^2/a`` (equal to the renderer's
   ``apparent_radius_px``), and ``range_km = R / sin(alpha)`` when the body radius is known
   (hints ``body_radii_km``/``body``; the Moon's 1737.4 km for ``body = "moon"``).
   Without a camera: the circle centre, no line of sight, no range.  A camera with lens
   distortion: the fitted pixel coordinates are undistorted first (the pinhole relations
   hold in ideal coordinates) and the body-centre image is distorted back.
   With ``LocateOptions(profile="lunar-lambert")`` the pixels are refitted with the physical
   limb profile of :mod:`jaxlimb.pipeline.profile` instead (same sphere-shape iteration): it
   removes the sigmoid's limb bias (0.1-0.6 px on realistic Moons).
5. covariance :math:`\hat\sigma^2 (J^\top J)^{-1}` of the final fit, propagated to the
   reported quantities (``center_r``, ``center_c``, ``radius`` ...) through the Jacobian of
   the map of step 4 (central differences); the Cramér--Rao bound at the estimate with
   :math:`\hat\sigma` as the noise level (:func:`jaxlimb.analysis.crlb.crlb`), propagated the
   same way.

The pixels of the final fit are returned in ``LimbMeasurement.selected_pixels_rc`` (not in
the JSON) for :func:`jaxlimb.pipeline.figure.save_locate_figure`.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import Any

import numpy as np

from ..errors import ConfigError, ConvergenceError, SaturationWarning
from ..geometry.camera import Camera
from ..imaging import Hints, check_prior, front_end, prior_from_hints, validate_image
from ..imaging import sun_direction_image
from ..models import CIRCLE, ELLIPSE, CircleParams, EllipseParams
from ..fitting import NormalLM, solver_from_name
from .sun_profile import LimbDarkenedParams, fit_limb_darkened, select_sun_annulus
from .profile import (
    LIMB_PROFILE,
    PROFILE_FIXED,
    LimbProfileParams,
    l_band,
    lunar_lambert_weight,
    sphere_from_circle_fit,
)
from .checks import (
    MIN_LIT_ARC_DEG,
    MIN_LIT_ARC_PROFILE_DEG,
    check_center_in_field,
    check_jump,
    check_lit_arc,
    check_radius_prior,
    check_size,
    jump_threshold,
    max_limb_displacement,
)
from .options import LocateOptions
from .refine import (
    FitData,
    RefineResult,
    _run,
    annulus_halfwidth,
    fit_circle_annulus,
    fit_ellipse_annulus,
    fit_sphere_annulus,
    fisher_information,
    predict,
    lit_halfangle,
    select_annulus,
    LOGISTIC_TO_GAUSS,
)
from .result import EllipseResult, LimbMeasurement
from .sphere import sphere_from_ellipse_center

#: Widen the annulus when it is narrower than this many Gaussian-equivalent edge sigmas.
_EDGE_SIGMAS = 4.5


def _as_hints(hints: Any) -> Hints | None:
    if hints is None or isinstance(hints, Hints):
        return hints
    if isinstance(hints, dict):
        return Hints.from_dict(hints)
    raise ConfigError(f"`hints` must be a jaxlimb.imaging.Hints, a dict or None, got {type(hints).__name__}")


def _as_camera(camera: Any) -> Camera | None:
    if camera is None or isinstance(camera, Camera):
        return camera
    if isinstance(camera, dict):
        return Camera.from_dict(camera)
    raise ConfigError(f"`camera` must be a jaxlimb.geometry.Camera, a dict or None, got {type(camera).__name__}")


def _pinhole(camera: Camera) -> Camera:
    return Camera(camera.focal_length_mm, camera.pixel_pitch_mm, camera.rows, camera.cols, camera.principal_point_rc)


def _propagate(fun, x0: np.ndarray, cov: np.ndarray, h: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """Jacobian of ``fun`` at ``x0`` by central differences and ``J cov J^T``."""
    y0 = np.asarray(fun(x0), dtype=float)
    J = np.empty((y0.size, x0.size))
    for j in range(x0.size):
        xp, xm = x0.copy(), x0.copy()
        xp[j] += h
        xm[j] -= h
        J[:, j] = (np.asarray(fun(xp)) - np.asarray(fun(xm))) / (2 * h)
    return J, J @ cov @ J.T


def _cov_dict(names: list[str], cov: np.ndarray) -> dict[str, dict[str, float]]:
    return {a: {b: float(cov[i, j]) for j, b in enumerate(names)} for i, a in enumerate(names)}


def _phase(hints: Hints, camera: Camera | None, center_rc) -> float:
    s = np.asarray(hints.sun_dir_camera, dtype=float)
    u = camera.los(np.asarray(center_rc, dtype=float)) if camera is not None else np.array([0.0, 0.0, 1.0])
    return float(np.arccos(np.clip(-s @ u, -1.0, 1.0)))  # Eq. (2) of Aerospace 2015


def locate(
    image: Any,
    camera: Camera | dict | None = None,
    hints: Hints | dict | None = None,
    options: LocateOptions | None = None,
    *,
    mask: np.ndarray | None = None,
) -> LimbMeasurement:
    """Locate the body in ``image``: centre of the body's image, radius, LOS and range.

    Parameters
    ----------
    image
        2-D grey image ``[row, col]`` (any numeric dtype; colour is converted with a warning).
    camera
        :class:`~jaxlimb.geometry.camera.Camera` (or its dict); enables the body-centre
        correction, the line of sight and the range.  Its size must match the image.
    hints
        :class:`~jaxlimb.imaging.Hints` (or the hints dict of DESIGN.md): body, radii,
        expected radius, range prior, Sun direction ...
    options
        :class:`~jaxlimb.pipeline.options.LocateOptions`.
    mask
        Validity mask (``True`` = measured pixel; :class:`jaxlimb.imaging.formats.Frame`);
        masked pixels are neither limb nor background.  With a camera and hints that predict
        the limb (``expected_center_rc``, ``range_prior_km``, radii: SPICE), the whole limb,
        lit and dark, is measured by :func:`jaxlimb.pipeline.whole_limb.locate_whole_limb`.

    Returns
    -------
    LimbMeasurement
        ``center_rc`` is the image of the **body centre** (with a camera) or the circle
        centre (without).  ``extras`` holds the front end's circle, the CSF circle before the
        correction, the annulus, the checks' numbers and the timings.

    Raises
    ------
    ImageContentError, ConfigError
        Unusable image / camera / hints / options (CLI exit 2).
    NoBodyError, TooSmallError, TooBigError, TooThinError, TooManyOutliersError,
    RadiusInconsistentError, CenterOutOfFieldError, ConvergenceError, JumpError, ArcTooShortError
        A check failed (CLI exit 3; :mod:`jaxlimb.pipeline.checks`).
    """
    opt = options if options is not None else LocateOptions()
    if not isinstance(opt, LocateOptions):
        raise ConfigError(f"`options` must be a LocateOptions, got {type(opt).__name__}")
    t0 = time.perf_counter()
    img = validate_image(image, reject_constant=False)
    cam = _as_camera(camera)
    hin = _as_hints(hints)
    if cam is not None and (cam.rows, cam.cols) != img.shape:
        raise ConfigError(f"camera size {cam.rows}x{cam.cols} does not match the image size {img.shape[0]}x{img.shape[1]}")
    if mask is not None and np.shape(mask) != img.shape:
        raise ConfigError(f"mask shape {np.shape(mask)} does not match the image size {img.shape}")
    if _limb_predicted(cam, hin):
        from .whole_limb import locate_whole_limb

        return locate_whole_limb(img, cam, hin, opt, mask=mask)
    if _arc_only(cam, hin, img.shape):
        # close approach: the disc exceeds the frame; measure the visible arc (too_big only without one)
        from .whole_limb import locate_arc

        return locate_arc(img, cam, hin, opt, mask=mask)

    # ------------------------------------------------------------------ Check 1 on the prior first
    # (Aerospace 2015 §3: "after internal parameter computation"): a body the hints say is too
    # small, too big or too thin is reported as such, before the image is searched
    fe_opt = opt.gradient if opt.front_end == "gradient" else opt.scanline
    if hin is not None:
        popt = getattr(fe_opt, "prior", None)
        pri0 = prior_from_hints(hin, cam, options=popt, check=True)
        if pri0 is not None and cam is None:
            check_prior(pri0, img.shape, popt)

    # ------------------------------------------------------------------ front end (Checks 1-4)
    cand = front_end(opt.front_end, img, None, hints=hin, camera=cam, options=fe_opt)
    t_fe = time.perf_counter()
    prior = cand.info.get("prior")

    # ------------------------------------------------------------------ annulus on the lit side
    dr = annulus_halfwidth(cand.radius, cand.residual_rms, opt)
    sun_known = hin is not None and hin.sun_dir_camera is not None
    phase = _phase(hin, cam, cand.center_rc) if sun_known else (prior.phase_rad if prior is not None else None)
    direction = cand.lit_direction
    if direction is None:
        half = math.pi
    elif sun_known:
        half = lit_halfangle(phase, cand.radius, dr, opt.horn_margin_deg)
    else:
        # Sun unknown: the arc of the front end's points, but never more than the lit
        # half-circle of the phase measured on the image (more is the dark limb / terminator)
        ph_img = prior.phase_rad if prior is not None else None
        half = min(cand.lit_halfangle + math.radians(2.0), lit_halfangle(ph_img, cand.radius, dr, opt.horn_margin_deg))
    sel = select_annulus(img, cand.center_rc, cand.radius, dr, direction, half, opt)
    # lit-arc check (cropped body, Sun-facing side out of the frame) before any fit
    physical = _use_profile(opt, hin)
    min_arc = float(opt.min_lit_arc_deg) if opt.min_lit_arc_deg is not None else (
        MIN_LIT_ARC_PROFILE_DEG if physical else MIN_LIT_ARC_DEG)
    check_lit_arc(sel.angles(), min_arc, half)
    circ = fit_circle_annulus(sel, opt)
    p = circ.fit.params
    widened = False
    if opt.estimate_k and opt.annulus_px is None:
        need = _EDGE_SIGMAS * LOGISTIC_TO_GAUSS / max(float(p.k), 1e-6)
        cap = max(opt.annulus_min_px, 0.5 * cand.radius)
        if need > 1.05 * dr and dr < cap:
            dr = min(cap, need)
            sel = select_annulus(img, (float(p.r0), float(p.c0)), float(p.radius), dr, direction, half, opt)
            circ = fit_circle_annulus(sel, opt)
            p = circ.fit.params
            widened = True
    # re-centre: the annulus (its levels per bin, its lit-side window) was built on the front
    # end's circle, which is px off when its arc is short or partly terminator (cropped bodies);
    # when the CSF moved the limb by more than half a pixel, reselect on the CSF circle and refit once
    recentred = False
    if max_limb_displacement(sel.center_rc, sel.radius, (float(p.r0), float(p.c0)), float(p.radius), sel.angles()) > 0.5:
        sel = select_annulus(img, (float(p.r0), float(p.c0)), float(p.radius), dr, direction, half, opt)
        circ = fit_circle_annulus(sel, opt)
        p = circ.fit.params
        recentred = True
    arc_deg = check_lit_arc(np.arctan2(circ.coords[:, 0] - float(p.r0), circ.coords[:, 1] - float(p.c0)), min_arc, half)
    t_fit = time.perf_counter()
    c_circ = (float(p.r0), float(p.c0))
    r_circ = float(p.radius)

    # ------------------------------------------------------------------ checks 5, 1, 4
    thr = jump_threshold(dr, opt.max_jump_px)
    jump = check_jump(cand.center_rc, cand.radius, c_circ, r_circ, sel.angles(), thr)
    min_diam = 10.0
    if opt.gradient is not None and opt.front_end == "gradient":
        min_diam = opt.gradient.prior.min_diameter_px  # type: ignore[attr-defined]
    check_size(r_circ, img.shape, min_diam)
    if prior is not None:
        check_radius_prior(r_circ, prior.radius_range, prior.source)
    check_center_in_field(c_circ, r_circ, img.shape)

    # ------------------------------------------------------------------ body centre, model
    body_radius_km = hin.radius_km() if hin is not None else None
    final = circ
    extras: dict[str, Any] = {}
    los = None
    range_km = None
    ellipse: EllipseResult | None = None
    radius_px: float | None = r_circ
    fitp = circ.fit.params
    use_camera = cam is not None and opt.body_center_correction
    pin = _pinhole(cam) if cam is not None else None

    def _to_observed(rc_ideal):
        if cam is not None and cam.has_distortion:
            return tuple(float(v) for v in cam.distort(np.asarray(rc_ideal, float)))
        return (float(rc_ideal[0]), float(rc_ideal[1]))

    sat = saturation_level(img)
    z_ann = circ.data.z if circ.data.weights is None else img[circ.coords[:, 0].astype(np.int64),
                                                                circ.coords[:, 1].astype(np.int64)]
    n_sat = int(np.count_nonzero(np.asarray(z_ann) >= sat)) if sat is not None else 0
    if n_sat >= 20:
        extras["saturation"] = {"level": sat, "n_clipped_in_annulus": n_sat, "n_annulus": int(len(z_ann))}
        warnings.warn(SaturationWarning(
            f"{n_sat} of the {len(z_ann)} pixels of the limb annulus are clipped at {sat:g}: the radius (range) may be "
            "biased outward by up to ~1 px; expose shorter"), stacklevel=2)
    profile_fit = None
    if physical:
        try:
            profile_fit, n_clipped = _fit_profile(img, circ, cam, hin, opt, use_camera, sat)
            if n_clipped and "saturation" in extras:
                extras["saturation"]["n_left_out_of_profile_fit"] = n_clipped
        except ConvergenceError as e:
            if opt.profile != "auto":
                raise
            # "auto": the sigmoid's answer stands; say why the refinement was not used
            extras["profile_rejected"] = {"model": "lunar-lambert", "reason": str(e)}
    band_L = l_band(profile_fit.fit) if profile_fit is not None else None
    if profile_fit is not None and opt.profile == "auto" and not band_L[0] <= float(profile_fit.fit.params.L) <= band_L[1]:
        # the limb is not lunar-Lambert-like (e.g. a flat disc): keep the sigmoid, say why
        extras["profile_rejected"] = {"model": "lunar-lambert", "L": float(profile_fit.fit.params.L),
                                      "allowed_L": list(band_L)}
        profile_fit = None
    if physical and profile_fit is None and opt.min_lit_arc_deg is None:
        # back on the sigmoid: its own (longer) shortest arc applies
        check_lit_arc(np.arctan2(circ.coords[:, 0] - c_circ[0], circ.coords[:, 1] - c_circ[1]), MIN_LIT_ARC_DEG, half)
    if _use_sun_profile(opt, hin):
        # the Sun: a self-luminous, limb-darkened disc (jaxlimb.pipeline.sun_profile)
        sun = fit_limb_darkened(img, c_circ, r_circ, solver=None if opt.solver == "lm" else solver_from_name(opt.solver))
        coords_s, z_s = select_sun_annulus(img, c_circ, r_circ, sun.annulus_px)
        held = tuple(n for n in LimbDarkenedParams.field_names() if n not in sun.fit.free)
        final = RefineResult(sun.fit, FitData(coords_s, z_s, None, 0.0, 1.0), 0, held)
    elif profile_fit is not None:
        final = profile_fit
    elif use_camera:
        assert cam is not None and pin is not None
        data_ideal = circ.data.with_coords(cam.undistort(circ.coords)) if cam.has_distortion else circ.data
        circle_ideal = fitp
        if cam.has_distortion:
            c_id = cam.undistort(np.array([float(fitp.r0), float(fitp.c0)]))
            circle_ideal = fitp.replace(r0=float(c_id[0]), c0=float(c_id[1]))
        f = cam.focal_px
        pp = cam.principal_point_rc
        final = fit_sphere_annulus(data_ideal, circle_ideal, f, pp, opt)
        sph = final.sphere
        assert sph is not None
        extras["limb_ellipse"] = {
            "center_rc": list(_to_observed(sph.ellipse_center_rc)),
            "semi_axes_px": [sph.a, sph.b],
            "angle_rad": sph.angle_rad,
        }

    if opt.model == "ellipse":
        if use_camera:
            q = final.fit.params
            start = EllipseParams(r0=q.r0, c0=q.c0, a=q.a, theta=q.theta, rho=min(float(q.rho), 0.999), k=q.k,
                                  ymax=q.ymax, ymin=q.ymin)
            data_e = final.data
        else:
            start = _ellipse_start(circ, cand)
            data_e = circ.data
        final = fit_ellipse_annulus(data_e, start, opt)

    fp = final.fit.params
    free = list(final.fit.free)
    cov_fit = np.asarray(final.fit.covariance)
    names_out: list[str]
    if isinstance(fp, (LimbProfileParams, LimbDarkenedParams)):
        names_geo = ["center_r", "center_c", "radius"]
        gidx = [free.index(n) for n in ("r0", "c0", "a")]
        x0 = np.array([float(fp.r0), float(fp.c0), float(fp.a)])
        if use_camera and isinstance(fp, LimbProfileParams):
            assert pin is not None

            def _out(x):
                s_ = sphere_from_ellipse_center(pin.focal_px, pin.principal_point_rc, (x[0], x[1]), x[2])
                bc = _to_observed(s_.body_center_rc)
                return np.array([bc[0], bc[1], s_.radius_equivalent_px])

            sph = sphere_from_ellipse_center(pin.focal_px, pin.principal_point_rc, (x0[0], x0[1]), x0[2])
            center = _to_observed(sph.body_center_rc)
            radius_px = sph.radius_equivalent_px
            los = tuple(float(v) for v in sph.los)
            if body_radius_km is not None:
                range_km = float(body_radius_km / math.sin(sph.alpha_rad))
            extras["limb_ellipse"] = {"center_rc": list(_to_observed(sph.ellipse_center_rc)),
                                      "semi_axes_px": [sph.a, sph.b], "angle_rad": sph.angle_rad}
            Jg, _ = _propagate(_out, x0, np.eye(3))
        else:
            center = (float(x0[0]), float(x0[1]))
            radius_px = float(x0[2])
            Jg = np.eye(3)
            if cam is not None:
                los = tuple(float(v) for v in cam.los(np.array(center)))
                if isinstance(fp, LimbDarkenedParams) and body_radius_km is not None:
                    range_km = float(body_radius_km / math.sin(math.atan(radius_px / cam.focal_px)))
        other = [i for i in range(len(free)) if i not in gidx]
        J = np.zeros((3 + len(other), len(free)))
        J[:3, gidx] = Jg
        for row, i in enumerate(other):
            J[3 + row, i] = 1.0
        names_out = names_geo + [free[i] for i in other]
        cov_out = J @ cov_fit @ J.T
    elif final.fit.params.__class__.__name__ == "CircleParams":
        # no camera (or correction disabled): circle centre and radius as fitted
        names_out = [{"r0": "center_r", "c0": "center_c"}.get(n, n) for n in free]
        center = (float(fp.r0), float(fp.c0))
        cov_out = cov_fit
        J = np.eye(len(free))
        if cam is not None:
            los = tuple(float(v) for v in cam.los(np.array(center)))
    else:
        geo = ("r0", "c0", "a", "theta", "rho")
        gidx = [i for i, n in enumerate(free) if n in geo]
        x0 = np.array([float(getattr(fp, free[i])) for i in gidx])
        full = {n: float(getattr(fp, n)) for n in geo}

        def _params_at(x):
            d = dict(full)
            for j, i in enumerate(gidx):
                d[free[i]] = float(x[j])
            return d

        if opt.model == "ellipse":
            a_, rho_, th_ = full["a"], full["rho"], full["theta"]
            if rho_ > 1.0:  # keep a >= b
                a_, rho_, th_ = a_ * rho_, 1.0 / rho_, th_ + math.pi / 2
            ellipse = EllipseResult(
                center_rc=_to_observed((full["r0"], full["c0"])),
                semi_axes_px=(a_, a_ * rho_),
                angle_rad=float(th_ % math.pi),
            )
            radius_px = None

            def _out(x):
                d = _params_at(x)
                if use_camera:
                    return np.array(_body_from_ellipse(pin, d) + (d["a"], d["rho"], d["theta"]))
                return np.array([d["r0"], d["c0"], d["a"], d["rho"], d["theta"]])

            geo_names = ["center_r", "center_c", "a", "rho", "theta"]
            if use_camera:
                bc = _body_from_ellipse(pin, full)
                center = _to_observed(bc)
                los = tuple(float(v) for v in pin.los(np.array(bc)))
                if body_radius_km is not None:
                    b_ = a_ * rho_
                    range_km = float(body_radius_km / math.sin(math.atan(b_ * b_ / (a_ * pin.focal_px))))
            else:
                center = ellipse.center_rc
        else:
            # the sphere-constrained ESF: (r0, c0, a) -> body centre, f tan(alpha)
            sph = final.sphere
            assert sph is not None and pin is not None

            def _out(x):
                d = _params_at(x)
                s = sphere_from_ellipse_center(pin.focal_px, pin.principal_point_rc, (d["r0"], d["c0"]), d["a"])
                bc = _to_observed(s.body_center_rc)
                return np.array([bc[0], bc[1], s.radius_equivalent_px])

            geo_names = ["center_r", "center_c", "radius"]
            center = _to_observed(sph.body_center_rc)
            radius_px = sph.radius_equivalent_px
            los = tuple(float(v) for v in sph.los)
            if body_radius_km is not None:
                range_km = float(body_radius_km / math.sin(sph.alpha_rad))
        Jg, _ = _propagate(_out, x0, np.eye(x0.size))
        other = [i for i in range(len(free)) if i not in gidx]
        J = np.zeros((len(geo_names) + len(other), len(free)))
        J[: len(geo_names), gidx] = Jg
        for row, i in enumerate(other):
            J[len(geo_names) + row, i] = 1.0
        names_out = geo_names + [free[i] for i in other]
        cov_out = J @ cov_fit @ J.T
    t_geo = time.perf_counter()

    crlb_out = None
    if opt.compute_crlb and isinstance(fp, (LimbProfileParams, LimbDarkenedParams)):
        # unit weights: the bound at the estimate with sigma-hat is sigma-hat^2 (J^T J)^-1, the
        # fit's own covariance (no second pass over the pixels)
        crlb_out = {n: float(math.sqrt(max(cov_out[i, i], 0.0))) for i, n in enumerate(names_out)}
    elif opt.compute_crlb:
        # the Cramér--Rao bound of jaxlimb.analysis.crlb at the estimate, sigma-hat as the noise
        # level, with the per-pixel weights of the level normalisation (noise sigma / w_i)
        model = CIRCLE if isinstance(fp, CircleParams) else ELLIPSE
        sigma = math.sqrt(max(float(final.fit.sigma2), 1e-300))
        try:
            cov_crlb = np.linalg.inv(fisher_information(model, fp, final.data, final.fixed, sigma))
            ccr = J @ cov_crlb @ J.T
            crlb_out = {n: float(math.sqrt(max(ccr[i, i], 0.0))) for i, n in enumerate(names_out)}
        except np.linalg.LinAlgError:  # pragma: no cover - singular Fisher matrix
            crlb_out = None
    t_end = time.perf_counter()

    if isinstance(fp, (LimbProfileParams, LimbDarkenedParams)):
        # report the logistic steepness equivalent to the fitted Gaussian edge, and amp + ymin as ymax
        s_e = math.sqrt(float(fp.sigma) ** 2 + 1.0 / 12.0)
        k_val, ymax_dn, ymin_dn = LOGISTIC_TO_GAUSS / s_e, float(fp.ymin) + float(fp.amp), float(fp.ymin)
        if isinstance(fp, LimbProfileParams):
            extras["profile"] = {"model": "lunar-lambert", "psf_sigma_px": float(fp.sigma), "amp": float(fp.amp),
                                 "phase_deg": math.degrees(float(fp.phase)), "L": float(fp.L)}
        else:
            extras["profile"] = {"model": "limb-darkened", "psf_sigma_px": float(fp.sigma), "amp": float(fp.amp),
                                 "u1": float(fp.u1), "u2": float(fp.u2)}
    else:
        k_val = float(fp.k)
        ymax_dn = float(final.data.offset + final.data.scale * float(fp.ymax))
        ymin_dn = float(final.data.offset + final.data.scale * float(fp.ymin))
    pix = None
    if opt.keep_pixels:
        pix = final.coords
        if use_camera and cam is not None and cam.has_distortion:
            pix = cam.distort(final.coords)
    extras.update(
        {
            "initial_circle": {"center_rc": list(cand.center_rc), "radius_px": cand.radius, "rms_px": cand.residual_rms},
            "circle_fit": {"center_rc": list(c_circ), "radius_px": r_circ},
            "annulus_px": dr,
            "annulus_widened": widened,
            "annulus_recentred": recentred,
            "lit_arc_deg": arc_deg,
            "lit_direction_rc": list(direction) if direction is not None else None,
            "lit_halfangle_deg": math.degrees(half),
            "sun_direction_known": bool(sun_known),
            "phase_deg": math.degrees(phase) if phase is not None else None,
            "n_angular_bins": [sel.n_bins_kept, sel.n_bins],
            "n_outliers": int(circ.n_outliers + (final.n_outliers if final is not circ else 0)),
            "jump_px": jump,
            "jump_limit_px": thr,
            "sigma_hat": math.sqrt(max(float(final.fit.sigma2), 0.0)) * final.data.scale,
            "levels_normalized": final.data.weights is not None,
            "k_estimated": bool(opt.estimate_k),
            "prior_source": prior.source if prior is not None else None,
            "timings_s": {
                "front_end": t_fe - t0,
                "refine": t_fit - t_fe,
                "body_center": t_geo - t_fit,
                "crlb": t_end - t_geo,
                "total": t_end - t0,
            },
        }
    )
    extras = {k: v for k, v in extras.items() if v is not None}
    return LimbMeasurement(
        center_rc=(float(center[0]), float(center[1])),
        radius_px=None if radius_px is None else float(radius_px),
        ellipse=ellipse,
        k=k_val,
        ymax=ymax_dn,
        ymin=ymin_dn,
        covariance=_cov_dict(names_out, cov_out),
        iterations=int(final.fit.n_steps) + (int(circ.fit.n_steps) if final is not circ else 0),
        solver=final.fit.solver,
        front_end=cand.front_end,
        n_pixels=int(final.fit.n_pixels),
        los_camera=los,
        range_km=range_km,
        crlb=crlb_out,
        extras=extras,
        selected_pixels_rc=pix,
    )


def _limb_predicted(cam: Camera | None, hin: Hints | None) -> bool:
    """The hints place the limb (SPICE-like prediction): the whole-limb stage applies."""
    return (cam is not None and not cam.has_distortion and hin is not None and hin.expected_center_rc is not None
            and hin.range_prior_km is not None and hin.radius_km() is not None)


def _arc_only(cam: Camera | None, hin: Hints | None, shape: tuple[int, int]) -> bool:
    """Camera, range and radius known, and the expected disc larger than the frame's half-diagonal."""
    if cam is None or cam.has_distortion or hin is None or hin.radius_km() is None or hin.range_prior_km is None:
        return False
    rkm, rng = hin.radius_km(), hin.range_prior_km
    return rng > rkm and cam.focal_px * math.tan(math.asin(rkm / rng)) > 0.5 * math.hypot(*shape)


def _use_profile(opt: LocateOptions, hin: Hints | None) -> bool:
    """``profile="auto"``: the physical profile for a sunlit body whose Sun direction is known
    (circle model, ``k`` estimated); the sigmoid otherwise."""
    if opt.profile != "auto":
        return opt.profile == "lunar-lambert"
    # the papers' fixed-k setting (Table 1) is a sigmoid experiment: keep the sigmoid there
    return (opt.model == "circle" and opt.estimate_k and hin is not None and hin.sun_dir_camera is not None
            and hin.body != "sun")


def _use_sun_profile(opt: LocateOptions, hin: Hints | None) -> bool:
    """The limb-darkened disc: asked for, or ``profile="auto"`` with hints ``body = "sun"``."""
    if opt.profile != "auto":
        return opt.profile == "limb-darkened"
    return opt.model == "circle" and opt.estimate_k and hin is not None and hin.body == "sun"


def _fit_profile(img: np.ndarray, circ, cam: Camera | None, hin: Hints | None, opt: LocateOptions, use_camera: bool,
                 sat: float | None = None):
    """Refit the pixels of the CSF with the physical lunar-Lambert limb profile (:mod:`jaxlimb.pipeline.profile`).

    ``sat``: the image's clip level (:func:`saturation_level`), if any.  Returns the
    :class:`~jaxlimb.pipeline.refine.RefineResult` and the number of clipped (saturated) pixels
    left out."""
    if hin is None or hin.sun_dir_camera is None:
        raise ConfigError("LocateOptions.profile = 'lunar-lambert' needs the Sun direction (hints `sun_dir_camera`)")
    p = circ.fit.params
    coords = circ.coords
    z = img[coords[:, 0].astype(np.int64), coords[:, 1].astype(np.int64)].astype(np.float64)
    center = (float(p.r0), float(p.c0))
    if use_camera and cam is not None and cam.has_distortion:
        coords = cam.undistort(coords)
        center = tuple(float(v) for v in cam.undistort(np.array(center)))
    s = np.asarray(hin.sun_dir_camera, dtype=float)
    u = cam.los(np.array([float(p.r0), float(p.c0)])) if cam is not None else np.array([0.0, 0.0, 1.0])
    phase = float(np.arccos(np.clip(-s @ u, -1.0, 1.0)))
    sun_rc = sun_direction_image(hin.sun_dir_camera, cam, (float(p.r0), float(p.c0)) if cam is not None else None)
    if sun_rc is None:
        sun_rc = (1.0, 0.0)  # full or new: the direction does not matter (sin(phase) ~ 0)
    if cam is not None:
        inv_f = 1.0 / cam.focal_px
    else:
        rng = hin.range_prior_km
        rkm = hin.radius_km()
        # without a camera the angular radius comes from the range prior (else orthographic)
        inv_f = (math.tan(math.asin(rkm / rng)) / float(p.radius)) if (rng and rkm and rng > rkm) else 0.0
    s_e = LOGISTIC_TO_GAUSS / max(float(p.k), 1e-6)
    sigma0 = math.sqrt(max(s_e * s_e - 1.0 / 12.0, 0.09))
    scale = float(circ.data.scale) if circ.data.weights is not None else float(p.ymax) - float(p.ymin)
    offset = float(circ.data.offset) if circ.data.weights is not None else float(p.ymin)
    init = LimbProfileParams(r0=center[0], c0=center[1], a=float(p.radius), theta=0.0, rho=1.0, sigma=sigma0,
                             amp=max(scale, 1e-6),
                             ymin=offset, sun_r=sun_rc[0], sun_c=sun_rc[1], phase=phase, inv_f=inv_f,
                             L=lunar_lambert_weight(phase) if opt.lunar_lambert_L is None else float(opt.lunar_lambert_L))
    data = FitData(coords, z, None, 0.0, 1.0)
    # L is estimated unless given: it adapts the profile to Lambert (0) ... Lommel-Seeliger (1) limbs
    fixed = PROFILE_FIXED if opt.lunar_lambert_L is not None else tuple(n for n in PROFILE_FIXED if n != "L")
    # the default solver with a tolerance on the parameters' own scale (px, DN): 1e-7 is
    # far below any measurable change; 1e-10 relative costs ~4 more passes for nothing
    solver = NormalLM(rtol=0.0, atol=1e-7) if opt.solver == "lm" else None
    n_clipped = 0
    if sat is not None and np.count_nonzero(z >= sat) >= 20:  # (a few hot pixels are not a clipped limb)
        # clipped pixels carry no value, and a sensor clips at its full well *before* the read
        # noise, so they scatter a few DN below the top code: fit the pixels 4 noise sigmas below
        # it, then keep those whose *model* value is (a selection that does not depend on the
        # noise) and refit.  The noise sigma: robust spread of the sky side of the annulus.
        d_c = np.hypot(coords[:, 0] - center[0], coords[:, 1] - center[1])
        sky = z[d_c > float(p.radius) + 3.0 * s_e]
        noise = 1.4826 * float(np.median(np.abs(sky - np.median(sky)))) if sky.size >= 20 else 1.0
        margin = 4.0 * max(noise, 0.5)
        keep = z < sat - margin
        n_clipped = int(np.count_nonzero(~keep))
        # the clipped interior hides the brightness profile that sets L: hold it (McEwen or given)
        fixed = PROFILE_FIXED
        res, sph = _profile_passes(data.subset(keep), init, cam, center, float(p.radius), opt, fixed, solver,
                                   use_camera)
        pred = predict(LIMB_PROFILE, res.params, coords)
        keep = (pred < sat - margin) & (z < sat)
        data = data.subset(keep)
        res, sph = _profile_passes(data, res.params, cam, None, None, opt, fixed, solver, use_camera)
    else:
        res, sph = _profile_passes(data, init, cam, center, float(p.radius), opt, fixed, solver, use_camera)
    return RefineResult(res, data, 0, fixed, sphere=sph), n_clipped


def saturation_level(img: np.ndarray) -> float | None:
    """The clip level of ``img`` if it has one: its maximum when >= 20 pixels sit exactly on it
    (noise never makes a plateau; clipping, including 12-bit data in 16-bit words, does)."""
    m = float(np.max(img))
    return m if np.count_nonzero(img == m) >= 20 else None


def _profile_passes(data: FitData, start: LimbProfileParams, cam: Camera | None, center, radius, opt: LocateOptions,
                    fixed, solver, use_camera: bool):
    """The profile fit (``center``/``radius``: the circle to start the sphere's shape from; ``None``:
    from ``start``).  With a camera, the sphere's ellipse shape is held fixed and iterated (as
    :func:`~jaxlimb.pipeline.refine.fit_sphere_annulus`).  The shape (``a - b`` ~ 5 px at the corner
    of the default imager for a 210 px Moon) changes by ~0.006 px per px of centre shift, so a
    second pass is run only when the shape at the fitted centre differs from the one fitted by
    more than 1e-3 px anywhere on the limb; it starts at the answer and needs no coarse phase."""
    if not use_camera or cam is None:
        return _run(LIMB_PROFILE, data, start, opt, fixed, solver), None
    f, pp = cam.focal_px, cam.principal_point_rc
    if center is not None:
        sph = sphere_from_circle_fit(f, pp, center, radius)
        q = start.replace(a=sph.a, theta=sph.angle_rad, rho=sph.rho)
    else:
        q = start
    res = sph = None
    for i in range(2):
        s_i = solver if (i == 0 or solver is None) else NormalLM(rtol=0.0, atol=1e-5, coarse_stride=1)
        res = _run(LIMB_PROFILE, data, q, opt, fixed, s_i)
        q = res.params
        sph = sphere_from_ellipse_center(f, pp, (float(q.r0), float(q.c0)), float(q.a))
        if _shape_change_px(q, sph) < 1e-3:
            break
        q = q.replace(theta=float(sph.angle_rad), rho=float(sph.rho))
    return res, sph


def _shape_change_px(q: LimbProfileParams, sph) -> float:
    """Largest radial change (px) of the limb ellipse of ``q`` if its axis ratio and orientation
    were those of ``sph`` (same ``a``): ``|d(a - b)| + (a - b) |d theta|``."""
    a = float(q.a)
    dab = abs(a * (1.0 - float(q.rho)) - a * (1.0 - float(sph.rho)))
    dth = abs(math.remainder(float(q.theta) - float(sph.angle_rad), math.pi))
    return dab + a * abs(1.0 - float(sph.rho)) * dth


def _body_from_ellipse(pin: Camera, d: dict[str, float]) -> tuple[float, float]:
    """Body-centre image (ideal px) of a free ellipse ``(r0, c0, a, rho, theta)`` of a sphere (exact)."""
    from ..geometry.navigation import sphere_from_ellipse

    a, rho = d["a"], d["rho"]
    if rho > 1.0:
        a, rho = a * rho, 1.0 / rho
    u, _ = sphere_from_ellipse(pin, (d["r0"], d["c0"]), (a, max(a * rho, 1e-9)), 1.0)
    bc = pin.project(u)
    return (float(bc[0]), float(bc[1]))


def _ellipse_start(circ, cand) -> EllipseParams:
    """Start of the free ESF without a camera: the CSF circle, orientation from an algebraic ellipse fit.

    ``rho`` starts at 0.995 (at exactly 1 the orientation column of the Jacobian vanishes);
    ``theta`` from :func:`cv2.fitEllipse` of the front end's limb points when it returns a
    near-circular ellipse (axis ratio > 0.8), else 0.
    """
    p = circ.fit.params
    theta = 0.0
    pts = np.asarray(cand.points_rc, dtype=np.float32)
    if pts.shape[0] >= 5:
        import cv2

        try:
            (_, _), (w, h), ang = cv2.fitEllipse(pts[:, ::-1].copy())
            if min(w, h) > 0.8 * max(w, h):
                # OpenCV: angle (deg) of the `w` axis from +x (col) toward +y (row); ours from +col toward -row
                major_deg = ang if w >= h else ang + 90.0
                theta = math.radians(-major_deg) % math.pi
        except cv2.error:  # pragma: no cover
            theta = 0.0
    return EllipseParams(r0=p.r0, c0=p.c0, a=p.radius, theta=theta, rho=0.995, k=p.k, ymax=p.ymax, ymin=p.ymin)


__all__ = ["locate"]
