r"""The ellipsoid strategy of :func:`jaxlimb.pipeline.locate` (the Earth; any spheroid): the stages that
differ from a sphere's.  The method (limb cone, elliptical edge with interior ramp, physical profile,
Earth offset and range iteration of Mortari, D'Souza & Zanetti 2016 §IV, Fig. 2) is described in
:mod:`jaxlimb.pipeline.earth`, which holds its geometry (:func:`earth_position_from_ellipse`).

* **prepare**: a camera is required (the range needs it); with lens distortion the frame is resampled
  onto the ideal pixel grid (the limb is a conic only there) and ``finish`` maps the centre and its
  covariance back through the distortion's Jacobian.
* **candidates**: the shared front end; when it fails on the radius or the outliers (its circle on cloud
  edges), the range prior's radius behind the disc's sunward extreme (:func:`_blob_candidates`).
* **limb pixels**: the lit window from the Sun direction (else the front end's arc) less
  ``arc_margin_deg`` at each horn (:class:`~jaxlimb.errors.ArcTooShortError` when nothing is left),
  and the band of half-width ``band_px`` about the current ellipse (:func:`~jaxlimb.pipeline.earth._band_pixels`).
  The ellipse is the limb traced against the sky (``EllipsoidOptions.trace``, :mod:`jaxlimb.pipeline.limb_trace`:
  the outermost edge along rays, not the front end's circle, which lies on cloud edges 7-19 px off on cloudy
  frames); on an albedo-patchy limb (clouds) the band is level-normalised per ray, rays with a cloud edge inside
  the band are left out, the edge is a plain step, the uniform-albedo profile is not fitted and the traced points'
  cluster-robust spread is added to the covariance as model error.  With the attitude known, the rays' own
  known-shape ellipse replaces the band fit when the band fit does not converge or leaves the rays' 95 % region
  (:func:`_patchy_geometry`), and the two estimates' difference is added to the covariance; a glow above a cloudy
  limb lifts the dim rays' edges more than the bright ones', and that lift (``c / A_ray``) is fitted beside the rays'
  ellipse when it is significant (:func:`_fit_rays`).  A front-end circle
  outside the range prior's 1-sigma radius band (on cloud edges) is replaced by the disc-and-prior start.
* **edge fit**: the elliptical sigmoid with interior ramp (:data:`jaxlimb.models.ELLIPSE_RAMP`), ``rho,
  theta`` predicted from the limb cone at the current position (``R_body_to_camera`` known; else or with
  ``model="ellipse"`` free), repeated while the prediction moves the ellipse; Checks 1, 3/4 (radius in the
  prior's band), 4 and 5 (jump from the front end's circle) as for a sphere.
* **profile refit**: the lunar-Lambert profile on the same pixels (Sun direction known), widened by a glow above
  the limb when the score test of the Moon's glow gate asks for it (:func:`~jaxlimb.pipeline.ellipsoid_profile.widen_glow_ellipsoid`).
* **body-centre mapping**: the range iteration; the covariance of ``(center_r, center_c, range_km)`` through
  its central-difference Jacobian; with a free ellipse the unsigned centre offset as a model error.

``estimate_k=False`` (the papers' fixed-``k`` sphere setting) is refused: the ellipsoid's edge model
estimates its kernel with the ramp.  ``model="ellipse"`` frees ``rho, theta``.  ``compute_crlb`` as for
every body (:func:`jaxlimb.pipeline.report.crlb`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, ClassVar, final

import equinox as eqx
import numpy as np

from ..fitting.jacobian import numerical_jacobian
from ..errors import ArcTooShortError, ConfigError, ConvergenceError, GeometryError, LimbInputError, RadiusInconsistentError, TooManyOutliersError
from ..fitting import fit, solver_from_name
from ..geometry.camera import Camera
from ..geometry.ellipsoid import check_rotation, image_conic
from ..imaging import sun_direction_image
from ..models import ELLIPSE, ELLIPSE_RAMP, EllipseParams, EllipseRampParams
from .checks import check_center_in_field, check_radius_prior, check_size, jump_threshold
from .earth import (
    EllipsoidOptions,
    _band_pixels,
    _band_signed,
    _ell_change,
    _spheroid,
    earth_position_from_ellipse,
    unsigned_offset_cov,
)
from .ellipsoid_profile import fit_profile_ellipsoid, floor_center_var
from .frame import candidates, min_diameter_px
from .report import check_physical
from .stages import Body, BodyCenter, Covariance, EllipsePixels, EllipsoidEdge, FitData, Frame, Levels, RefineResult
from .result import EllipseResult, LimbMeasurement


@final
@dataclass(frozen=True)
class Ellipsoid(Body[EllipsePixels, EllipsoidEdge]):
    """The ellipsoid strategy (module docstring)."""

    eo: EllipsoidOptions
    equatorial_km: float
    polar_km: float
    atmosphere_km: float
    R: np.ndarray | None
    free: bool
    name: ClassVar[str] = "ellipsoid"

    @classmethod
    def for_frame(cls, frame: Frame) -> "Ellipsoid":
        """Validate what the ellipsoid needs (camera, spheroid radii, rotation) and refuse what it cannot honour."""
        opt, h = frame.opt, frame.hints
        if frame.cam is None:
            raise ConfigError("the ellipsoid strategy (hints body 'earth') needs a camera (`camera`; the CLI's --camera): "
                              "it measures the range")
        if not opt.estimate_k:
            raise ConfigError("estimate_k = False (the papers' fixed-k sphere setting) is not available for the "
                              "ellipsoid: its edge model estimates the kernel with the interior ramp")
        if opt.profile == "limb-darkened":
            raise ConfigError("profile = 'limb-darkened' is the disc strategy's (the Sun), not the ellipsoid's")
        eo = opt.ellipsoid if opt.ellipsoid is not None else EllipsoidOptions()
        if not isinstance(eo, EllipsoidOptions):
            raise ConfigError(f"LocateOptions.ellipsoid must be an EllipsoidOptions, got {type(eo).__name__}")
        h = h if h is not None else _earth_hints()
        Re, Rp, atm = _spheroid(h)
        R = None if h.R_body_to_camera is None else check_rotation(np.asarray(h.R_body_to_camera), "R_body_to_camera",
                                                                   tol=1e-6)
        free = True if opt.model == "ellipse" else (eo.free_ellipse if eo.free_ellipse is not None else R is None)
        return cls(eo, Re, Rp, atm, R, bool(free))

    @property
    def radii_limb(self) -> np.ndarray:
        a, c, h = self.equatorial_km, self.polar_km, self.atmosphere_km
        return np.array([a + h, a + h, c + h])

    @property
    def pole(self) -> np.ndarray | None:
        return None if (self.free or self.R is None) else self.R[:, 2]

    def _solver(self, frame: Frame):  # noqa: ANN202
        return None if frame.opt.solver == "lm" else solver_from_name(frame.opt.solver)

    # ------------------------------------------------------------------------------------------- stages
    def prepare(self, frame: Frame) -> Frame:
        """Lens distortion: measure in the ideal image (resampled), the observed camera kept for ``finish``."""
        cam = frame.cam
        if frame.hints is None or frame.hints.body is None:
            frame = replace(frame, hints=_earth_hints(frame.hints))
        if cam is None or not cam.has_distortion:
            return frame
        from ..imaging.undistort import pinhole_of, undistort_image

        return replace(frame, img=undistort_image(frame.img, cam), cam=pinhole_of(cam), observed_cam=cam)

    def candidates(self, frame: Frame) -> Any:
        """The shared front end; when it fails on the limb's size or outliers (its circle on cloud edges: a 37 px
        circle for a 124 px Earth) and the trace is on, the disc's outermost lit pixel and the range prior's
        radius (:func:`_blob_candidates`) start the trace instead; so they do when the front end's radius lies
        outside the range prior's 1-sigma band (``Prior.radius_uncertainty_frac``: its 3-sigma RANSAC band let
        circles on cloud edges through)."""
        try:
            cand = candidates(frame)
        except (RadiusInconsistentError, TooManyOutliersError):
            start = _blob_candidates(self, frame) if self.eo.trace else None
            if start is None:
                raise
            return start
        prior = cand.info.get("prior")
        if (self.eo.trace and prior is not None and prior.expected_radius_px
                and abs(cand.radius / prior.expected_radius_px - 1.0) > prior.radius_uncertainty_frac):
            # a circle on cloud edges that RANSAC's 3-sigma band let through (61 and 168 px for 124-127 px Earths,
            # benchmarks/families.py Earth ``clouds`` 3, 5): the trace cannot reach the limb from it (it searches
            # 20 % of the radius); start from the disc and the prior's radius instead
            start = _blob_candidates(self, frame)
            if start is not None:
                return replace(start, info={**start.info, "prior": prior})
        return cand

    def limb_pixels(self, frame: Frame, cand: Any) -> EllipsePixels:
        """The position prior, the lit window (arc check) and the initial ellipse."""
        cam, h, eo = frame.cam, frame.hints, self.eo
        c_rc = np.array(cand.center_rc, float)
        rl = self.equatorial_km + self.atmosphere_km
        D0 = h.range_prior_km or rl / math.sin(math.atan(cand.radius / cam.focal_px))
        if not D0 > rl:
            raise GeometryError(f"range prior {D0:.6g} km puts the observer inside the Earth (radius {rl:.6g} km)")
        p0 = -D0 * cam.los(c_rc)  # observer relative to the body centre, camera frame
        lit_dir, half = cand.lit_direction, cand.lit_halfangle
        sd = sun_direction_image(h.sun_dir_camera, cam, tuple(c_rc)) if h.sun_dir_camera is not None else None
        if sd is not None:
            lit_dir, half = sd, math.pi / 2
        if lit_dir is not None:
            half = min(half, math.pi / 2) - math.radians(eo.arc_margin_deg)
            if half <= math.radians(5):
                raise ArcTooShortError(
                    f"the lit limb arc left after {eo.arc_margin_deg:g} deg at each horn spans "
                    f"{max(0.0, 2 * math.degrees(half)):.3g} deg (at least 10 deg needed): too short for the ellipse")
        rho, th = (0.999, 0.0) if self.R is None else self._predicted_shape(cam, -p0)
        a0 = cand.radius / math.sqrt(rho)
        half = half if lit_dir is not None else math.pi
        ell = ((float(c_rc[0]), float(c_rc[1])), (a0, a0 * rho), th)
        if not eo.trace:
            return EllipsePixels(p0, float(D0), lit_dir, half, ell)
        ell, tr = _traced_start(frame.img, ell, lit_dir, half, eo.band_px, _ray_shading(self, frame))
        return EllipsePixels(p0, float(D0), lit_dir, half, ell, tr)

    def _predicted_shape(self, cam: Camera, center_km: np.ndarray) -> tuple[float, float]:
        ic = image_conic(cam, self.radii_limb, center_km, self.R)
        return float(ic.rho), float(ic.angle_rad)

    def edge_fit(self, frame: Frame, cand: Any, pix: EllipsePixels) -> EllipsoidEdge:
        """The ramp ESF loop (module docstring), then Checks 1, 3/4, 4, 5 on the fitted ellipse."""
        edge = _edge_loop(self, frame, pix)
        if pix.patchy and not self.free:
            edge = _patchy_geometry(self, frame, edge)
        (r0, c0), (a, b), _ = edge.fitted
        # the jump first (as for the sphere, edge.check_edge): a fit that collapsed from a 400 px circle to a point
        # was reported as a body too small to measure (a full-disc cloudy Earth, benchmarks/earth_full_disc.py)
        edge = _check_jump(frame, cand, edge, self.eo)
        check_size(0.5 * (a + b), frame.img.shape, min_diameter_px(frame))
        prior = cand.info.get("prior")
        if prior is not None:
            check_radius_prior(0.5 * (a + b), prior.radius_range, prior.source)
        check_center_in_field((r0, c0), a, frame.img.shape)
        return edge

    def report(self, frame: Frame, cand: Any, edge: EllipsoidEdge) -> dict[str, Any]:
        prior = cand.info.get("prior")
        return {"initial_circle": {"center_rc": list(cand.center_rc), "radius_px": cand.radius,
                                   "n_points": cand.n_points},
                "edge_fit": {"model": edge.final.fit.params.__class__.__name__, "fits": edge.history,
                             "ellipse_center_rc": list(edge.fitted[0]), "semi_axes_px": list(edge.fitted[1]),
                             "range_km": float(np.linalg.norm(edge.p))},
                "fits": edge.history, "range_prior_km": edge.pixels.range_prior_km, "free_ellipse": self.free,
                "atmosphere_km": self.atmosphere_km, "jump_px": edge.jump_px, "jump_limit_px": edge.jump_limit_px,
                "sun_direction_known": frame.sun_known, "prior_source": prior.source if prior is not None else None}

    def refit(self, frame: Frame, cand: Any, edge: EllipsoidEdge, extras: dict[str, Any]) -> RefineResult:
        """The lunar-Lambert profile on the edge fit's pixels (Sun direction known), else the edge fit; the centre's
        variance floored at ``EllipsoidOptions.center_floor_px``."""
        return floor_center_var(fit_profile_ellipsoid(self, frame, edge, extras), self.eo.center_floor_px ** 2)

    def body_center(self, frame: Frame, edge: EllipsoidEdge, final: RefineResult) -> BodyCenter:
        return ellipsoid_center(self, frame, final)

    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        check_physical(frame, levels, cov, self.name)

    def iterations(self, edge: EllipsoidEdge, final: RefineResult) -> int:
        # the edge fit with its model-error term is the same fit (same data), the profile a second one
        return edge.n_steps + (int(final.fit.n_steps) if type(final.fit.params) is not type(edge.final.fit.params) else 0)

    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """Distorted camera: ``center_rc`` and its covariance rows mapped to the observed image."""
        cam = frame.observed_cam
        if cam is None:
            return meas
        c_id = np.asarray(meas.center_rc, float)
        Jd = numerical_jacobian(lambda x: cam.distort(x), c_id, 1e-3)
        names = list(meas.covariance)
        P = np.array([[meas.covariance[a][b] for b in names] for a in names])
        T = np.eye(len(names))
        idx = [names.index("center_r"), names.index("center_c")]
        T[np.ix_(idx, idx)] = Jd
        P = T @ P @ T.T
        cov = {a: {b: float(P[i, j]) for j, b in enumerate(names)} for i, a in enumerate(names)}
        c_obs = cam.distort(c_id)
        pix = None if meas.selected_pixels_rc is None else cam.distort(np.asarray(meas.selected_pixels_rc, float))
        extras = {**meas.extras, "ellipse_frame": "ideal (undistorted) pixels", "undistorted_image": True}
        return replace(meas, center_rc=(float(c_obs[0]), float(c_obs[1])), covariance=cov, selected_pixels_rc=pix,
                       extras=extras)


def _blob_candidates(body: Ellipsoid, frame: Frame) -> Any:
    """A start without the front end (:meth:`Ellipsoid.candidates`): the radius ``f tan(asin(Re / D))`` of the range
    prior ``D`` and the centre ``R`` px behind the brightest-side extreme of the disc (the pixel above the sky
    by 5 noise sigma farthest toward the Sun's image direction); ``None`` without a camera, range prior or Sun."""
    from ..imaging import LimbCandidates

    cam, h, img = frame.cam, frame.hints, np.asarray(frame.img, float)
    if cam is None or h is None or not h.range_prior_km or h.sun_dir_camera is None:
        return None
    rl = body.equatorial_km + body.atmosphere_km
    if not h.range_prior_km > rl:
        return None
    R = cam.focal_px * math.tan(math.asin(rl / h.range_prior_km))
    from scipy.ndimage import label

    dark = img[img <= np.percentile(img, 70)]  # the sky (the disc covers < 30 % of a frame it fits in)
    sky, noise = float(np.median(dark)), max(float(np.std(dark)), 1e-6 * float(np.ptp(img)), 1e-12)
    lab, n = label(img > sky + 5.0 * noise)
    if n == 0:
        return None
    sizes = np.bincount(lab.ravel())[1:]
    rr, cc = np.nonzero(lab == 1 + int(np.argmax(sizes)))  # the disc: the largest bright component
    if rr.size < 50:
        return None
    c_mid = (float(np.median(rr)), float(np.median(cc)))
    sd = sun_direction_image(h.sun_dir_camera, cam, c_mid)
    if sd is None:
        return None
    proj = rr * sd[0] + cc * sd[1]
    far = proj >= np.percentile(proj, 99.9)
    p = np.array([np.median(rr[far]), np.median(cc[far])])
    c = p - R * np.asarray(sd, float)
    return LimbCandidates(np.zeros((0, 2)), (float(c[0]), float(c[1])), float(R), math.nan, tuple(sd), math.pi / 2,
                          "range prior + disc extreme", {"fallback": "front end failed"})


def _ray_shading(body: "Ellipsoid", frame: Frame) -> Any:
    """The uniform disc's shading for the trace's flatness test (:class:`~jaxlimb.pipeline.limb_trace.RayShading`,
    lunar-Lambert ``EllipsoidOptions.patchy_shading_L``), ``None`` without the Sun direction or with the option off."""
    from .limb_trace import RayShading

    L, sun = body.eo.patchy_shading_L, frame.hints.sun_dir_camera
    return None if L is None or sun is None else RayShading(frame.cam, tuple(float(x) for x in sun), float(L))


def _wide_trace(img: np.ndarray, ell: tuple, lit_dir, half: float, shade: Any) -> Any:
    """The start's wide trace (20 % of the radius deep) -- with the shading-flattened flatness test
    (:class:`~jaxlimb.pipeline.limb_trace.RayShading`) when the shading explains the plain test's rejections (a
    uniform disc would fail it on half the rays or more, :meth:`~jaxlimb.pipeline.limb_trace.RayShading.dark_share`:
    a dark Lambert limb near zero phase) and the flattened test keeps more rays, traced about ``ell`` or, when that
    keeps fewer than the plain test, about the plain rays' own fit.  Every other frame keeps its trace (a
    cloudy limb under a glow and a smear at 58 deg of phase, ``benchmarks/families.py`` Earth ``combined`` 2, went from
    0.09 to 1.32 px when its rays were flattened: the flattened trace is not tested for a glow, :func:`_rays_once`).
    (Also requiring the plain test to keep under one ray in ten left mottled frames whose brighter stretches passed
    it to the one-albedo profile: ``benchmarks/earth_mottled.py`` maps 8-12, NEES 4-45.)"""
    from .limb_trace import fit_traced, trace_limb

    search = max(12.0, 0.2 * ell[1][0])
    tr = trace_limb(img, ell, lit_dir, half, search)
    if shade is None or shade.dark_share(ell, tr.angles) < 0.5:
        return tr
    flat = trace_limb(img, ell, lit_dir, half, search, shade=shade)
    if flat.ok.sum() <= tr.ok.sum() and tr.ok.sum() >= 20:
        # the shading is placed on the reference ellipse: about a start 1 px off (on a cloud edge) the flattened
        # trace kept 24 rays of 321, about the plain rays' own fit 270 (benchmarks/earth_mottled.py map 15, 10 deg)
        flat = trace_limb(img, fit_traced(tr, ell), lit_dir, half, search, shade=shade)
    return flat if flat.ok.sum() > max(tr.ok.sum(), 20) else tr


def _traced_start(img: np.ndarray, ell: tuple, lit_dir, half: float, band: float,
                  shade: Any = None) -> tuple[tuple, Any]:
    """The initial ellipse from the limb against the sky (:mod:`jaxlimb.pipeline.limb_trace`): a wide trace about the
    front end's ellipse (it may lie on cloud edges: the search reaches 20 % of the radius; :func:`_wide_trace`), a
    fit, a narrow trace about it and a second fit; returns the ellipse and the narrow trace (its per-ray levels
    normalise the band; it carries the wide trace's ``shade`` to every later trace). A front-end ellipse
    within 1 px (median) of the traced points is kept (replacing it by the fit of a few traced rays sent one far
    ``lambert`` frame's free ellipse to a 1.3 px centre sigma)."""
    from .limb_trace import fit_traced, trace_limb

    try:
        tr = _wide_trace(img, ell, lit_dir, half, shade)
        narrow = max(6.0, 2.0 * band)
        on_limb = bool(tr.ok.sum()) and np.median(np.abs(_band_signed(tr.points[tr.ok], ell))) < 1.0
        if on_limb and tr.ok.sum() < 20:
            return ell, trace_limb(img, ell, lit_dir, half, narrow, shade=tr.shade)
        e1 = fit_traced(tr, ell)
        if on_limb and _ell_change(ell, e1) < 1.0:
            # the front end's ellipse is on the traced limb: it stays the start (the trace only gives the levels).
            # (Not when the rays' own fit lies elsewhere: on a full-disc cloudy Earth the front end's circle, 10 px
            # inside on cloud edges, had half the wide trace's crossings within 1 px and the rays' fit 0.3 px from the
            # limb; benchmarks/earth_full_disc.py ``clouds`` 0.)
            return ell, trace_limb(img, ell, lit_dir, half, narrow, shade=tr.shade)
        tr = trace_limb(img, e1, lit_dir, half, narrow, shade=tr.shade)
        e2 = fit_traced(tr, e1)
    except TooManyOutliersError:  # too few rays with a flat inside (a bright glow's foot): the front end's ellipse
        return ell, None
    if not (abs(e2[1][0] / ell[1][0] - 1.0) < 0.2 and math.dist(e2[0], ell[0]) < 0.2 * ell[1][0]):
        return ell, None  # the robust fit ran off (a few rays on a short arc): the front end's ellipse
    return e2, tr


def _band_data(img: np.ndarray, ell: tuple, band: float, pix: "EllipsePixels") -> FitData:
    """The band's pixels and values; with a trace, level-normalised per ray (rays without a limb against the
    sky, or with a cloud edge inside the band, left out: :func:`~jaxlimb.pipeline.limb_trace.normalised_band`)."""
    pts = _band_pixels(img.shape, ell, band, pix.lit_dir, pix.half)
    if pix.patchy:
        from .limb_trace import normalised_band

        return normalised_band(img, pts, pix.trace)[1]
    return FitData(pts, np.asarray(img[pts[:, 0].astype(int), pts[:, 1].astype(int)], float), None, 0.0, 1.0)


def _earth_hints(h: Any = None) -> Any:
    from ..imaging import Hints

    return Hints(body="earth") if h is None else replace(h, body="earth")


def _first_levels(img: np.ndarray, pts: np.ndarray, z: np.ndarray, ell: tuple, band: float) -> tuple[float, float]:
    F = _band_signed(pts, ell)
    inner, outer = z[F < -0.5 * band], z[F > 0.5 * band]
    ymax = float(np.median(inner)) if inner.size else float(np.percentile(z, 90))
    ymin = float(np.median(outer)) if outer.size else float(np.percentile(z, 10))
    return ymax, ymin


def _edge_start(eo: EllipsoidOptions, ell: tuple, prev: Any, levels: tuple[float, float]) -> Any:
    """The edge model's start: the current ellipse, the previous fit's other parameters (or the levels)."""
    (r0, c0), (a, b), th = ell
    geo = dict(r0=r0, c0=c0, a=a, theta=th, rho=b / a)
    if prev is not None:
        return prev.replace(**geo)
    kw = dict(**geo, k=eo.k_init, ymax=levels[0], ymin=levels[1])
    return EllipseRampParams(**kw, g=0.0, g2=0.0, h1=0.0, h2=0.0, h3=0.0, h4=0.0) if eo.interior_ramp else EllipseParams(**kw)


def _as_ellipse(P: Any) -> tuple:
    """The fitted ellipse ``((r0, c0), (a, b), theta)`` with ``a >= b``, ``theta`` in ``[0, pi)``."""
    a, rho, th = float(P.a), float(P.rho), float(P.theta)
    if a <= 0 or rho <= 0:
        raise ConvergenceError(f"the elliptical edge fit gave a non-physical ellipse: a = {a}, rho = {rho}")
    b = rho * a
    if b > a:  # a free fit may swap the axes: keep a >= b, theta along a
        a, b, th = b, a, th + math.pi / 2
    return ((float(P.r0), float(P.c0)), (a, b), th % math.pi)


def _edge_loop(body: Ellipsoid, frame: Frame, pix: EllipsePixels) -> EllipsoidEdge:
    """Steps 2-5 of the module docstring of :mod:`jaxlimb.pipeline.earth`: fit, range iteration, predicted
    shape, refit while the prediction moves the ellipse by more than ``refit_tol_px``.  On a patchy limb with the
    attitude known a band fit that does not converge returns its start (``band_converged=False``) for the rays'
    fit instead of raising."""
    eo, cam, img = body.eo, frame.cam, frame.img
    model = ELLIPSE_RAMP if eo.interior_ramp else ELLIPSE
    fixed = (() if body.free else ("rho", "theta")) + (tuple(eo.fix_profile) if eo.interior_ramp else ())
    if pix.patchy and eo.interior_ramp:  # per-ray levels and a flat interior (limb_trace): a plain step
        fixed = fixed + tuple(n for n in ("g", "g2", "h1", "h2", "h3", "h4") if n not in fixed)
    ell, p, prev, res, hist = pix.ellipse, pix.p0, None, None, []
    rays = pix.patchy and not body.free  # a band fit that does not converge is not the end (_patchy_geometry)
    for it in range(eo.max_refits):
        data = _band_data(img, ell, eo.band_px, pix)
        pts, z = data.coords, data.z
        if pts.shape[0] < 50:
            raise TooManyOutliersError(f"only {pts.shape[0]} pixels in the lit limb band (need >= 50)")
        init = _edge_start(eo, ell, res.params if res is not None else None,
                           _first_levels(img, pts, z, ell, eo.band_px) if res is None else (0.0, 0.0))
        res = fit(model, pts, z, init, body._solver(frame), fixed=fixed, weights=data.weights, throw=not rays)
        if not bool(res.converged):  # a patchy limb's band fit lost on cloud edges: the rays answer (_patchy_geometry)
            hist.append({"fit": it + 1, "converged": False, "fit_steps": int(res.n_steps)})
            final = RefineResult(eqx.tree_at(lambda x: x.params, res, init), data, 0,
                                 tuple(n for n in model.param_names if n not in res.free))
            return EllipsoidEdge(final, pix, pix.ellipse, position(body, cam, pix.ellipse, p)[0], hist, 0.0, 0.0,
                                 band_converged=False)
        fitted = _as_ellipse(res.params)
        p, info = position(body, cam, fitted, p)
        hist.append({"fit": it + 1, "range_km": float(np.linalg.norm(p)), "range_iterations": info["iterations"],
                     "fit_steps": int(res.n_steps)})
        if body.free:
            done, ell = prev is not None and _ell_change(prev, fitted) < eo.refit_tol_px, fitted
            prev = fitted
        else:  # the shape predicted at the new position; refit only if it moves the ellipse noticeably
            rho, th = body._predicted_shape(cam, -p)
            ell = (fitted[0], (fitted[1][0], fitted[1][0] * rho), th)
            done = _ell_change(fitted, ell) < eo.refit_tol_px
        if done:
            break
    frame.mark("refine")
    final = RefineResult(res, data, 0, tuple(n for n in model.param_names if n not in res.free))
    return EllipsoidEdge(final, pix, fitted, p, hist, 0.0, 0.0)


def _ray_geometry(body: Ellipsoid, frame: Frame, edge: EllipsoidEdge, passes: int = 2) -> EllipsoidEdge:
    """An albedo-patchy limb's geometry from its rays, not from the band fit (attitude known): the known-shape
    ellipse through the traced limb points (:func:`~jaxlimb.pipeline.limb_trace.fit_traced`, soft-L1), the rays
    re-sampled about it and the shape re-predicted at its position, ``passes`` times, starting from the traced
    start ellipse.  Why: the band fit of the level-normalised pixels pulls ``(r0, c0, a)`` with the cloud edges
    0-5 px inside the limb that survive the per-ray flatness test (``benchmarks/families.py`` Earth ``clouds``
    frame 1, 127 px: the band fit 4.2 px off, its traced start 0.8 px), while the ray fit weighs each ray's
    limb point once.  The edge fit's other parameters (levels, kernel) are kept; its ``(r0, c0, a)`` covariance
    is replaced by the rays' cluster-robust one in the refit stage
    (:func:`~jaxlimb.pipeline.ellipsoid_profile.fit_profile_ellipsoid`).  Returns the edge with its
    ``pixels.trace`` the last trace."""
    from .limb_trace import trace_limb

    pix, cam = edge.pixels, frame.cam
    search = max(6.0, 2.0 * body.eo.band_px)
    ell, p, tr, fitted = pix.ellipse, edge.p, pix.trace, pix.ellipse
    for _ in range(passes):
        rho, th = body._predicted_shape(cam, -p)
        ell = (ell[0], (ell[1][0], ell[1][0] * rho), th)
        tr, fitted, shift = _rays_once(body, frame, trace_limb(frame.img, ell, pix.lit_dir, pix.half, search,
                                                                shade=tr.shade), ell)
        p, _ = position(body, cam, fitted, p)
        ell = fitted
    return replace(_with_ellipse(edge, fitted), pixels=replace(pix, trace=tr, ray_fit=True), p=p, shading_shift=shift)


def _rays_once(body: Ellipsoid, frame: Frame, tr: Any, ell: tuple) -> tuple[Any, tuple, tuple | None]:
    """One pass of :func:`_ray_geometry` on trace ``tr`` about ``ell``: the rays' ellipse (:func:`_fit_rays`) with the
    crossings' shading bias removed (:func:`_shaded`), and the shift ``(dr0, dc0, da)`` that removal made (``None``
    when it was not made).  The glow's lift and the shading model do not compose (``combined`` 2-4 moved 0.1-0.2 px),
    so a glow fitted on the raw crossings is kept alone -- except on a shading-flattened trace (a dark Lambert limb,
    :class:`~jaxlimb.pipeline.limb_trace.RayShading`), whose raw crossings lie 0.6-0.8 px inside the limb, deepest
    where the limb is darkest: a ``c / A_ray`` lift takes that for a glow (the mottled Earth at 2 deg phase,
    ``benchmarks/earth_mottled.py``, 0.89 px off; tested after the shading's removal it still fitted one, 0.76 px).
    There only the shading is removed: a glow above a dark limb is not modelled (such a trace arises only near zero
    phase, :func:`_wide_trace`)."""
    from .limb_trace import fit_traced

    def moved(a: tuple, b: tuple) -> tuple:
        return (a[0][0] - b[0][0], a[0][1] - b[0][1], a[1][0] - b[1][0])

    if tr.shade is not None:
        plain, shaded = fit_traced(tr, ell), _shaded(body, frame, tr, ell)
        fitted = fit_traced(shaded, ell)
        return shaded, fitted, moved(fitted, plain)
    tr, fitted = _fit_rays(tr, ell, glow_tilt=_glow_tilt(frame, ell[0]))
    shaded = tr if tr.glow_term else _shaded(body, frame, tr, ell)
    if shaded is tr:
        return tr, fitted, None
    corrected = fit_traced(shaded, ell)
    return shaded, corrected, moved(corrected, fitted)


def _with_ellipse(edge: EllipsoidEdge, fitted: tuple) -> EllipsoidEdge:
    """``edge`` answering ellipse ``fitted`` (``fitted`` and its final fit's ``r0, c0, a, rho, theta``)."""
    (r0, c0), (a, b), th = fitted
    P = edge.final.fit.params.replace(r0=r0, c0=c0, a=a, rho=b / a, theta=th)
    return replace(edge, final=replace(edge.final, fit=eqx.tree_at(lambda x: x.params, edge.final.fit, P)), fitted=fitted)


def _shifted(edge: EllipsoidEdge, shift: tuple | None) -> EllipsoidEdge:
    """``edge`` with its ``(r0, c0, a)`` moved by ``shift`` (the rays' shading correction, :func:`_ray_geometry`): the
    band fit of the level-normalised pixels assumes the same flat inside as the rays' half-level crossings."""
    if shift is None:
        return edge
    (r0, c0), (a, b), th = edge.fitted
    return _with_ellipse(edge, ((r0 + shift[0], c0 + shift[1]), (a + shift[2], (a + shift[2]) * b / a), th))


def _shaded(body: Ellipsoid, frame: Frame, tr: Any, ell: tuple) -> Any:
    """The traced rays with their crossings' shading bias removed (``EllipsoidOptions.patchy_shading_L``; needs the
    Sun direction); ``tr`` unchanged without it or with fewer than 20 rays."""
    from .limb_trace import shading_corrected, shading_offsets, shading_sigma

    sh = _ray_shading(body, frame)
    if sh is None or tr.ok.sum() < 20:
        return tr
    sig = shading_sigma(frame.img, tr, ell, frame.cam, sh.sun_dir_camera, sh.L)
    return shading_corrected(tr, shading_offsets(tr, ell, frame.cam, sh.sun_dir_camera, sig, sh.L))


GLOW_TILT_MAX_PHASE_DEG = 20.0
"""At or below this phase (deg) a glow fitted above a patchy limb (:func:`_fit_rays`) carries its tilt toward the Sun
in the covariance (:func:`~jaxlimb.pipeline.limb_trace.glow_lift_columns`).  A glow is sunlight scattered by the
atmosphere at the limb's tangent points, whose solar zenith angle is ``acos(sin(phase) cos(psi))``: at 20 deg of
phase or less it is 70 deg or more all along the lit limb, where the twilight glow changes fast with it (the full disc
from L1, 4-12 deg: the uniform lift left ``benchmarks/earth_full_disc.py``'s held-out ``combined`` 0 and 2 0.54 and
0.56 px off along the Sun at NEES 49 and 14).  On a gibbous limb most tangent points are in full sunlight and the
glow is nearly uniform: there the tilt's marginal only widened the sigmas, past the tolerance on
``benchmarks/families.py``'s Earth ``combined`` 2 and 3 (39-58 deg; 0.09 and 0.20 px off at NEES 3.1 and 1.7)."""


def _glow_tilt(frame: Frame, center_rc) -> bool:
    """Whether the phase at the body's image ``center_rc`` (Sun known) is at most :data:`GLOW_TILT_MAX_PHASE_DEG`."""
    return frame.sun_known and math.degrees(frame.phase(center_rc)) <= GLOW_TILT_MAX_PHASE_DEG


def _fit_rays(tr: Any, ell: tuple, glow_tilt: bool = False) -> tuple[Any, tuple]:
    """The known-shape ellipse through the traced rays (:func:`~jaxlimb.pipeline.limb_trace.fit_traced`), with the
    glow's lift ``c / A_ray`` fitted beside it when it is positive at more than
    :data:`~jaxlimb.pipeline.limb_trace.GLOW_LIFT_Z` cluster-robust sigmas
    (:func:`~jaxlimb.pipeline.limb_trace.fit_traced_glow`; the returned trace then has ``glow_term`` set, so its
    covariance carries the lift too, and :func:`_patchy_geometry` answers with the rays: the band fit has no glow).

    Why: a glow above a cloudy limb (``benchmarks/families.py`` Earth ``combined``) adds the same radiance over ocean
    and cloud, so it lifts the half-level crossings of the dim ocean rays ten times more than the cloud rays': the
    traced limb is an ellipse pushed out by 0.3-0.9 px where the limb is dim (``combined`` 0, 4), and that part of it
    which varies along the arc moves the centre.  Measured with the truth ellipse as the trace's reference (centre
    error / radius error px, without -> with the lift): ``combined`` 2 0.44 / 0.30 -> 0.06 / 0.08, 4 0.91 / 1.66 ->
    0.28 / 0.36, 3 0.18 / 0.57 -> 0.19 / 0.24, 1 0.28 / 0.32 -> 0.43 / -0.27; no ``clouds`` frame passes the gate.
    In the pipeline (``locate``, attitude known): ``combined`` 2 0.290 -> 0.086 px (range -0.27 -> -0.02 %), 3 0.340 ->
    0.186 px, 1 and 4 measured at 0.51 and 0.32 px (NEES 2.3, 1.6) instead of ``center_too_uncertain``; frames 6-13 of
    the same seed (not tuned on): the two ``ok`` answers 1.006 / 1.297 px (NEES 21, 3.9) -> 0.106 / 0.143 px, one
    1.3 px answer now a typed failure.  (At 380 000 km the inside level ``P``, 2-5 px deep, is surface 10-16 deg from
    the limb, a poorer proxy of the limb's own radiance: ``combined`` 1 moved 0.41 -> 0.51 px.)"""
    from dataclasses import replace as _replace

    from .limb_trace import GLOW_LIFT_Z, fit_traced, fit_traced_glow

    e, c, z = fit_traced_glow(tr, ell)
    if c > 0.0 and z > GLOW_LIFT_Z:  # near zero phase its tilt too, in the covariance (GLOW_TILT_MAX_PHASE_DEG)
        return _replace(tr, glow_term=True, glow_tilt=glow_tilt), e
    return tr, fit_traced(tr, ell)


def _patchy_geometry(body: Ellipsoid, frame: Frame, edge: EllipsoidEdge, chi2: float = 5.99) -> EllipsoidEdge:
    """An albedo-patchy limb (attitude known) measured twice: the band fit of the level-normalised pixels (``edge``) and
    the known-shape ellipse through the traced rays (:func:`_ray_geometry`). The band fit is kept unless its centre lies
    outside the rays' 95 % region (``d^T C_rays^-1 d > chi2`` on ``(r0, c0)``, ``C_rays`` the rays' cluster-robust
    covariance, :func:`~jaxlimb.pipeline.limb_trace.trace_model_cov`): then the band fit ran after cloud edges
    (``benchmarks/families.py`` Earth ``clouds`` frame 1: 4.2 px off, the rays 1.4 px) and the rays' ellipse is the
    answer; so it is when the band fit did not converge (no witness then). Either way the other estimate's
    ``(r0, c0, a)`` is kept as ``witness``: two models of the same limb, their difference is model error (added to the
    covariance by :func:`~jaxlimb.pipeline.ellipsoid_profile.fit_profile_ellipsoid`, as a rejected profile's is)."""
    from .limb_trace import trace_model_cov

    try:
        rays = _ray_geometry(body, frame, edge)
    except TooManyOutliersError:  # fewer than 20 rays with a limb against the sky: the band fit alone, if any
        if edge.band_converged:
            return edge
        raise
    asym = _asymmetry(frame.img, rays.fitted, rays.pixels.lit_dir, rays.pixels.half, rays.pixels.trace.shade)
    if not edge.band_converged:
        return replace(rays, asymmetry=asym)

    def geo(e: EllipsoidEdge) -> np.ndarray:
        return np.array([e.fitted[0][0], e.fitted[0][1], e.fitted[1][0]])

    d = geo(edge) - geo(rays)
    C = trace_model_cov(rays.pixels.trace, rays.fitted, bias_reduced=False)[:2, :2]
    try:
        m2 = float(d[:2] @ np.linalg.solve(C, d[:2]))
    except np.linalg.LinAlgError:
        m2 = math.inf
    if m2 > chi2 or rays.pixels.trace.glow_term:  # (the band fit has no glow: the rays' lift answers)
        return replace(rays, witness=tuple(float(v) for v in geo(edge)), asymmetry=asym)
    return replace(_shifted(edge, rays.shading_shift), witness=tuple(float(v) for v in geo(rays)), asymmetry=asym)


def _asymmetry(img: np.ndarray, ell: tuple, lit_dir, half: float,
               shade: Any = None) -> tuple[float, float, float] | None:
    """The traced step's asymmetry as a witness of the patchy limb's centre: the known-shape ellipse ``ell`` (start)
    through the rays' 30 % crossings less the one through their 70 % crossings, ``(dr0, dc0, 0)``.  A symmetric
    blurred step moves only the radius between the two (by ~1 PSF sigma; left out, it is the step's width, not an
    error); a glow on the sky side, a smear, or an albedo change within the PSF depth that varies along the limb moves
    the centre (about the traced start on ``benchmarks/families.py`` Earth frames: ``combined`` 0 and 2, 0.36 and 0.58
    px; ``clouds`` 0, 0.16 px; the uniform ``own`` 0, 0.009 px).  As in Hausman's (1978) specification test, the
    difference of two estimators that agree when the model holds.  ``None`` if either fit fails."""
    from .limb_trace import fit_traced, trace_limb

    out = []
    try:
        for level in (0.3, 0.7):
            tr = trace_limb(img, ell, lit_dir, half, 8.0, level=level, shade=shade)
            e = fit_traced(tr, ell)
            out.append(np.array([e[0][0], e[0][1]]))
    except TooManyOutliersError:
        return None
    d = out[0] - out[1]
    return (float(d[0]), float(d[1]), 0.0)


def _check_jump(frame: Frame, cand: Any, edge: EllipsoidEdge, eo: EllipsoidOptions) -> EllipsoidEdge:
    """Check 5: the fitted ellipse must lie within ``max(2, band/2) + (a - b)`` px of the front end's circle on
    the fitted arc (the circle cannot follow the ellipse's out-of-roundness ``a - b``)."""
    from ..errors import JumpError

    pts = edge.final.coords
    if edge.pixels.trace is not None:  # the initial conic is the traced ellipse, not the front end's circle
        from ..geometry.ellipsoid import ellipse_points

        e0 = edge.pixels.ellipse
        ang = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
        on_circle = ellipse_points(e0[0], e0[1], e0[2], ang)
        arc = np.abs(np.angle(np.exp(1j * (np.arctan2(on_circle[:, 0] - e0[0][0], on_circle[:, 1] - e0[0][1])
                                          - np.arctan2(*(edge.pixels.lit_dir or (0.0, 1.0))))))) <= edge.pixels.half
        on_circle = on_circle[arc]
    else:
        ang = np.arctan2(pts[:, 0] - cand.center_rc[0], pts[:, 1] - cand.center_rc[1])
        on_circle = np.column_stack([cand.center_rc[0] + cand.radius * np.sin(ang),
                                     cand.center_rc[1] + cand.radius * np.cos(ang)])
    disp = float(np.max(np.abs(_band_signed(on_circle, edge.fitted)))) if pts.size else math.inf
    (_, _), (a, b), _ = edge.fitted
    thr = jump_threshold(eo.band_px, frame.opt.max_jump_px) + (a - b)
    if not disp <= thr:
        raise JumpError(f"Check 5: the elliptical fit moved the limb by up to {disp:.3g} px from the front end's "
                        f"circle (limit {thr:.3g} px)")
    return replace(edge, jump_px=disp, jump_limit_px=thr)


def position(body: Ellipsoid, cam: Camera, fitted: tuple, p0: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """The observer position from a fitted ellipse (range iteration); no convergence is a failed check."""
    try:
        return earth_position_from_ellipse(
            cam, *fitted, p0, pole_camera=body.pole, equatorial_km=body.equatorial_km, polar_km=body.polar_km,
            atmosphere_km=body.atmosphere_km, eps_rad=body.eo.eps_rad, max_iter=body.eo.max_iter)
    except ConvergenceError:
        raise
    except LimbInputError as e:  # a bad ellipse (no limb cone): not a measurement of this body
        raise ConvergenceError(f"the fitted ellipse does not give a position: {e}") from None


def ellipsoid_center(body: Ellipsoid, frame: Frame, final: RefineResult) -> BodyCenter:
    """Stage "body-centre mapping" of the ellipsoid: the range iteration from the final fit's ellipse and its
    central-difference Jacobian; outputs ``center_r, center_c, range_km, a`` (and ``rho, theta`` when free)."""
    cam, P = frame.cam, final.fit.params
    fitted = _as_ellipse(P)
    p, info = position(body, cam, fitted, frame_position_start(final, body, cam, fitted))
    geo = ("r0", "c0", "a") + (("rho", "theta") if body.free else ())
    outputs = ("center_r", "center_c", "range_km") + geo[2:]

    def g(x: np.ndarray) -> np.ndarray:
        q = P.replace(**dict(zip(geo, (float(v) for v in x))))
        pp, _ = position(body, cam, _as_ellipse(q), p)
        rc = cam.project(-pp)
        return np.concatenate([[rc[0], rc[1], np.linalg.norm(pp)], x[2:]])

    x0 = np.array([float(getattr(P, n)) for n in geo])
    G = numerical_jacobian(g, x0, np.array([1e-3, 1e-3, 1e-3, 1e-5, 1e-4][: len(geo)]))
    rng = float(np.linalg.norm(p))
    model_cov, goff = None, 0.0
    center, los, pole_report = cam.project(-p), -p / rng, None
    if body.free:
        model_cov, goff = unsigned_offset_cov(cam, fitted, rng, body.equatorial_km, body.polar_km, body.atmosphere_km,
                                              len(outputs))
        marg = _pole_marginal(body, frame, final, p)
        if marg is not None:
            center, model_cov[:2, :2], pole_report = marg
            los = cam.los(np.asarray(center, float))
    (c, (a, b), th) = fitted
    model = {"LimbProfileParams": "lunar_limb", "GlowProfileParams": "lunar_limb_glow", "AnisoProfileParams": "lunar_limb_aniso",
             "EllipseRampParams": "ellipse_ramp"}.get(type(P).__name__, "ellipse")
    extras = {"model": model, "ellipse_center_rc": list(c), "rho": b / a, "theta_rad": th, "gamma_off_rad": float(info["gamma_off_rad"]),
              "gamma_off_unsigned_model_rad": goff, "a_prime": info["a_prime"], "b_prime": info["b_prime"]}
    if pole_report is not None:
        extras["pole_prior"] = pole_report
    return BodyCenter(tuple(float(v) for v in center), None,
                      EllipseResult(center_rc=c, semi_axes_px=(a, b), angle_rad=th), tuple(float(v) for v in los),
                      rng, outputs, geo, G, model_cov, extras)


def _pole_marginal(body: Ellipsoid, frame: Frame, final: RefineResult, p: np.ndarray) -> tuple | None:
    """The free ellipse's body centre marginalised over the poles the Sun's declination bound allows
    (``EllipsoidOptions.sun_declination_max_deg``, :func:`jaxlimb.pipeline.pole_prior.marginal_center`): its image,
    covariance and a report; ``None`` when the option is off, the pole is known, the Sun unknown or no pole fits."""
    from .pole_prior import FREE_ELLIPSE, marginal_center

    dmax, sun = body.eo.sun_declination_max_deg, frame.hints.sun_dir_camera
    free = list(final.fit.free)
    if dmax is None or body.R is not None or sun is None or not all(n in free for n in FREE_ELLIPSE):
        return None
    idx = [free.index(n) for n in FREE_ELLIPSE]
    C = np.asarray(final.fit.covariance, float)[np.ix_(idx, idx)]
    Re, Rp = body.radii_limb[0], body.radii_limb[2]
    out = marginal_center(frame.cam, final.fit.params, C, -p, sun, math.sin(math.radians(dmax)), Re, Rp)
    if out is None:
        return None
    mean, cov, rep = out
    return mean, cov, {**rep, "sun_declination_max_deg": float(dmax)}


def frame_position_start(final: RefineResult, body: Ellipsoid, cam: Camera, fitted: tuple) -> np.ndarray:
    """The range iteration's start: the free-ellipse position of ``fitted`` (``(Re + h) / a'`` along the cone axis)."""
    free = Ellipsoid(body.eo, body.equatorial_km, body.polar_km, body.atmosphere_km, None, True)
    return position(free, cam, fitted, np.zeros(3))[0]


__all__ = ["Ellipsoid", "ellipsoid_center", "position"]
