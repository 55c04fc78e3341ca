r"""The limb as the boundary against space: the outermost edge along rays from the centre (ellipsoid strategy).

A cloudy Earth has interior albedo edges (cloud against ocean: albedo 0.75 against 0.06) as strong as the
limb, and its limb's brightness changes by an order of magnitude along the arc (a cloud over the limb, then
ocean).  A gradient front end takes cloud edges for limb points (its circle was 7-19 px off on
:mod:`jaxlimb.render.independent`'s ``clouds`` frames) and a band fit with one inside level is pulled by
them.  What tells the limb from every cloud edge is that it is the *last* transition before the sky: along
each ray from the centre, outward, nothing brighter than the sky follows it.

:func:`trace_limb` samples rays across the lit window (one per px of arc) from ``search`` px inside to
``search`` px outside the current ellipse and, on each ray,

1. the sky level ``s`` and its noise ``sigma`` (median and MAD of the outer third of all rays' samples);
2. the outermost sample brighter than ``s + 5 sigma`` (the limb's outer foot; nothing brighter lies outside);
3. the inside level ``P``: the median over 2-5 px inside that foot; the ray is kept when ``P - s >= 8 sigma``
   and that interior is flat (range within ``flat_frac (P - s)``: no cloud edge within the band's depth);
4. the limb point: the outermost crossing of ``(s + P) / 2`` (linear interpolation), the 50 % point of a
   symmetric blurred step (the edge models' convention, :mod:`jaxlimb.pipeline.earth`).

:func:`fit_traced` fits the ellipse (shape held: ``rho, theta``) to the points with a robust (soft-L1)
geometric cost; :func:`fit_traced_glow` adds a glow's lift of each ray's crossing, ``c / (P_ray - s)``
(:func:`glow_lift_column`), for a glow above a cloudy limb.  The per-ray levels normalise the band's pixels for the edge and profile fits
(:func:`normalised_band`): ``z_n = (z - s) / (P_ray - s)`` with weights ``(P_ray - s) / C_ref`` (as the
sphere's ``normalize_levels``, :class:`jaxlimb.pipeline.refine.FitData`), i.e. an inside level that may vary
from ray to ray, and the pixels of rejected rays (faint, or a cloud edge inside the band) left out.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace

import numpy as np

from ..fitting.jacobian import numerical_jacobian
from ..fitting.model_error import cluster_robust_bias_reduced, cluster_robust_covariance
from ..errors import TooManyOutliersError
from .earth import _band_signed
from .refine import FitData


PATCHY_TOL = 0.1
FEW_RAYS_RMS = 0.03


@dataclass(frozen=True)
class TracedLimb:
    """Rays of :func:`trace_limb`: polar angles (rad, about ``center_rc``), limb points ``(n, 2)`` (NaN where the
    ray was rejected), inside levels ``P`` (NaN likewise), the sky level and its noise; ``lit_angle``: the polar
    angle of the lit side's direction (the Sun's image direction when known), which a glow's tilt is measured from;
    ``glow_tilt``: with ``glow_term``, the covariance carries the glow's tilt too (:func:`glow_lift_columns`)."""

    center_rc: tuple[float, float]
    angles: np.ndarray
    points: np.ndarray
    inside: np.ndarray
    sky: float
    noise: float
    glow_term: bool = False
    shade: "RayShading | None" = None
    albedo: np.ndarray | None = None
    lit_angle: float | None = None
    glow_tilt: bool = False

    @property
    def ok(self) -> np.ndarray:
        return np.isfinite(self.inside)

    def patchy(self, tol: float = PATCHY_TOL) -> bool:
        """Whether the limb's inside level varies along the arc by more than a smooth photometric fade does:
        the RMS of ``log P`` about its second-order harmonic fit in the ray angle exceeds ``tol`` (0.1: 10 %).
        Lambert-like fading toward the horns is a first/second harmonic; an albedo map (clouds over an
        ocean: 0.75 against 0.06) is not.  Also patchy: fewer than one ray in ten kept (a uniform disc keeps
        18-99 % on ``benchmarks/families.py``'s ``own`` frames, a cloudy one with motion blur and glow 3 %) when the
        kept rays' levels are not as level as a uniform disc's (RMS above :data:`FEW_RAYS_RMS`: without the attitude,
        traced about a front-end circle 4 px off, four uniform Earths kept 4-10 % of their rays at RMS 0.006-0.014 and
        one, ``lambert`` 4, was measured as a patchy limb 1.4 px off; the cloudy frames' RMS is 0.14-0.49)."""
        ok = self.ok & (self.inside > self.sky)
        if self.albedo is not None:
            ok &= self.albedo > 0
        if ok.sum() < 20:
            return False
        t = self.angles[ok]
        if self.albedo is not None:
            return _albedo_patchy(t, np.log(self.albedo[ok]))
        rms = _harmonic_rms(t, np.log(self.inside[ok] - self.sky))
        # nine rays in ten with no flat inside against the sky: an albedo map (clouds), unless the rays kept are as
        # level as a uniform disc's (RMS <= FEW_RAYS_RMS)
        return bool(rms > tol or (ok.mean() < 0.1 and rms > FEW_RAYS_RMS))


PATCHY_ALBEDO_TOL = 0.04
"""RMS (of ``log``) of the albedo along a shading-flattened trace's rays above which the limb is patchy."""


def _harmonic_rms(t: np.ndarray, y: np.ndarray) -> float:
    """RMS of ``y`` about its second-order harmonic fit in the ray angle ``t``."""
    A = np.column_stack([np.ones_like(t), np.cos(t), np.sin(t), np.cos(2 * t), np.sin(2 * t)])
    r = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
    return float(np.sqrt(np.mean(r * r)))


def _albedo_patchy(t: np.ndarray, y: np.ndarray) -> bool:
    """:meth:`TracedLimb.patchy` for a shading-flattened trace (:class:`RayShading`): ``y`` is each ray's ``log``
    albedo (its window divided by the uniform disc's shading), which a uniform disc keeps level to the noise.  Patchy
    when its RMS about the second-order harmonic fit exceeds both :data:`PATCHY_ALBEDO_TOL` and twice the ray
    noise (from neighbouring rays' differences, which an albedo map that changes slowly along the limb leaves out;
    pure noise gives an RMS of about the noise).  ``log P`` would not do: the shading makes it vary along a dark limb
    (``benchmarks/earth_mottled.py`` at 2 deg phase: RMS 0.042 for the uniform disc, 0.094 for map 4; the albedo's
    0.015 and 0.083, ray noise 0.012 and 0.017).  Map 9, traced about the start ellipse: 0.080 for a noise of 0.033
    (three times the noise called it uniform, and the one-albedo profile answered 1.5 px off, NEES 12)."""
    noise = 1.4826 * float(np.median(np.abs(np.diff(y)))) / math.sqrt(2.0)
    return _harmonic_rms(t, y) > max(PATCHY_ALBEDO_TOL, 2.0 * noise)


def _ray_radius(ell: tuple, u: np.ndarray) -> np.ndarray:
    """Distance from the ellipse centre to the ellipse along unit directions ``u`` ``(n, 2)`` (two first-order
    steps of :func:`_band_signed`)."""
    c = np.asarray(ell[0], float)
    r = np.full(u.shape[0], float(ell[1][0]))
    for _ in range(3):
        r = r - _band_signed(c + r[:, None] * u, ell)
    return r


def _ray_angles(ell: tuple, lit_dir, half: float) -> np.ndarray:
    a = float(ell[1][0])
    if lit_dir is None:
        return np.linspace(-math.pi, math.pi, max(64, int(2 * math.pi * a)), endpoint=False)
    t0 = math.atan2(lit_dir[0], lit_dir[1])
    return t0 + np.linspace(-half, half, max(16, int(2 * half * a)))


def _sample_rays(img: np.ndarray, ell: tuple, angles: np.ndarray, search: float, step: float):
    from scipy.ndimage import map_coordinates

    u = np.column_stack([np.sin(angles), np.cos(angles)])
    s = np.arange(-search, search + 0.5 * step, step)
    rad = _ray_radius(ell, u)[:, None] + s[None, :]
    c = np.asarray(ell[0], float)
    rr, cc = c[0] + rad * u[:, 0:1], c[1] + rad * u[:, 1:2]
    inside = (rr >= 0) & (rr <= img.shape[0] - 1) & (cc >= 0) & (cc <= img.shape[1] - 1)
    v = map_coordinates(np.asarray(img, float), [rr.ravel(), cc.ravel()], order=1, mode="nearest").reshape(rr.shape)
    return np.where(inside, v, np.nan), rad, u


def _sky(v: np.ndarray) -> tuple[float, float]:
    outer = v[:, -max(3, v.shape[1] // 3):]
    outer = outer[np.isfinite(outer)]
    if outer.size == 0:
        raise TooManyOutliersError("the limb trace found no sky outside the limb (every ray leaves the frame)")
    sky = float(np.median(outer))
    mad = float(np.median(np.abs(outer - sky)))
    spread = float(np.nanpercentile(v, 99)) - sky
    return sky, max(1.4826 * mad, float(np.std(outer)), 1e-3 * abs(spread), 1e-12)


def _crossing(vv: np.ndarray, rad: np.ndarray, level: np.ndarray, last: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per ray: the outermost crossing (radius, linear interpolation) of ``level`` at or inside sample ``last``,
    and the index of the sample just inside it."""
    n, m = vv.shape
    j = np.arange(m)
    above = (vv >= level[:, None]) & (j[None, :] <= last[:, None])
    jo = np.where(above.any(axis=1), m - 1 - np.argmax(above[:, ::-1], axis=1), 0)
    jc = np.clip(jo, 0, m - 2)
    k = np.arange(n)
    v0, v1 = vv[k, jc], vv[k, jc + 1]
    frac = np.clip((v0 - level) / np.where(v0 - v1 > 0, v0 - v1, np.inf), 0.0, 1.0)
    return rad[k, jc] + frac * (rad[k, jc + 1] - rad[k, jc]), jo


def _window_stats(vv: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per ray: median and range (max - min) of the samples ``lo <= j <= hi`` (NaN where empty)."""
    j = np.arange(vv.shape[1])
    win = (j[None, :] >= lo[:, None]) & (j[None, :] <= hi[:, None])
    med = np.nanmedian(np.where(win, vv, np.nan), axis=1) if win.any() else np.full(vv.shape[0], np.nan)
    rng = np.where(win, vv, -np.inf).max(axis=1) - np.where(win, vv, np.inf).min(axis=1)
    return med, rng


def _ray_edges(v: np.ndarray, rad: np.ndarray, sky: float, noise: float, step: float, flat_frac: float,
               level: float = 0.5, shade_rows: np.ndarray | None = None):
    """Steps 2-4 of the module docstring on every ray: the limb's radius along the ray and the inside level; with
    ``shade_rows`` (a uniform disc's radiance on the same samples, :class:`RayShading`) the flatness of step 3 is
    tested on the samples divided by it, and the third value is each ray's albedo (the window's median of that
    ratio; ``None`` without ``shade_rows``).  (Tried: the level 2-5 px inside the half crossing, iterated from the
    foot, so that a bright glow's foot does not set it: on the ``clouds`` frames it climbed onto cloud edges inside
    the ocean limb, centres 0.6-2.9 px off instead of 0.1-0.5 px.)"""
    m = v.shape[1]
    vv = np.where(np.isfinite(v), v, sky)
    bright = vv > sky + 5.0 * noise
    foot = np.where(bright.any(axis=1), m - 1 - np.argmax(bright[:, ::-1], axis=1), -1)
    i0, i1 = int(round(2.0 / step)), int(round(5.0 / step))
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # empty windows (rays off the frame): NaN, rejected below
        P, spread = _window_stats(vv, foot - i1, foot - i0)
        r_edge, jo = _crossing(vv, rad, sky + level * (P - sky), foot)
        flat, fmed = spread <= flat_frac * (P - sky), None
        if shade_rows is not None:
            cut = 1e-3 * np.nanmax(shade_rows, axis=1, keepdims=True)
            ratio = (vv - sky) / np.where(shade_rows > cut, shade_rows, np.nan)
            fmed, frng = _window_stats(ratio, foot - i1, foot - i0)
            flat = frng <= flat_frac * fmed
    amp = P - sky
    ok = (foot - i1 >= 0) & (foot < m - 1) & (amp >= 8.0 * noise) & flat
    ok &= (jo >= 1) & (jo < m - 1)
    albedo = None if fmed is None else np.where(ok, fmed, np.nan)
    return np.where(ok, r_edge, np.nan), np.where(ok, P, np.nan), albedo


def trace_limb(img: np.ndarray, ell: tuple, lit_dir, half: float, search: float, *, step: float = 0.5,
               flat_frac: float = 0.35, level: float = 0.5, shade: "RayShading | None" = None) -> TracedLimb:
    """Trace the limb along rays across the lit window about ellipse ``ell`` (module docstring); ``level``: the
    crossing's fraction of the step (0.5, the edge; others measure the step's asymmetry, see
    :func:`jaxlimb.pipeline.ellipsoid._asymmetry`); ``shade``: test the inside's flatness on the rays divided by a
    uniform disc's shading (:class:`RayShading`)."""
    angles = _ray_angles(ell, lit_dir, half)
    v, rad, u = _sample_rays(img, ell, angles, search, step)
    sky, noise = _sky(v)
    rows = None if shade is None else shade.rows(ell, angles, np.arange(-search, search + 0.5 * step, step))
    r_edge, P, albedo = _ray_edges(v, rad, sky, noise, step, flat_frac, level, rows)
    c = np.asarray(ell[0], float)
    pts = c[None, :] + r_edge[:, None] * u
    lit_angle = None if lit_dir is None else math.atan2(lit_dir[0], lit_dir[1])
    return TracedLimb((float(c[0]), float(c[1])), angles, pts, P, sky, noise, shade=shade, albedo=albedo,
                      lit_angle=lit_angle)


SHADE_FINE = 0.05
"""The fine grid (px) on which :func:`shading_offsets` blurs its shading model."""


def _limb_normals(cam, ell: tuple, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per ray angle: the outward surface normal at the limb ``n0`` (camera frame, perpendicular to the line of sight)
    and the unit vector ``v`` toward the observer from the centre of ellipse ``ell`` (a sphere's limb)."""
    c = np.asarray(ell[0], float)
    v = -np.asarray(cam.los(c), float)
    u = np.column_stack([np.sin(angles), np.cos(angles)])
    d3 = np.asarray(cam.los(c[None, :] + 5.0 * u), float) + v[None, :]  # each ray's image direction in 3-D
    n0 = d3 - (d3 @ v)[:, None] * v[None, :]
    return n0 / np.linalg.norm(n0, axis=1, keepdims=True), v


def _pixel_blur(psf_sigma_px: float) -> float:
    """The Gaussian sigma (px) of a PSF of ``psf_sigma_px`` sampled by square pixels (variance + 1/12)."""
    return math.hypot(psf_sigma_px, math.sqrt(1.0 / 12.0))


def _shaded_rows(normals: tuple, sun_dir_camera, R: float, sigma: float, L: float, xs: np.ndarray) -> np.ndarray:
    """Rows of a uniform disc's radiance sampled at ``xs`` (px, outward from the limb) on the rays of ``normals``
    (:func:`_limb_normals`): lunar-Lambert shading ``2L mu0/(mu0 + mu) + (1 - L) mu0`` on a sphere of radius ``R`` px
    under the Sun ``sun_dir_camera`` (any length), blurred by a Gaussian of ``sigma`` px."""
    from scipy.ndimage import gaussian_filter1d

    n0, v = normals
    sun = np.asarray(sun_dir_camera, float) / np.linalg.norm(sun_dir_camera)
    xf = np.arange(xs[0] - 4.0 * sigma - 2.0, xs[-1] + 4.0 * sigma + 2.0, SHADE_FINE)
    th = np.arccos(np.clip(1.0 - np.clip(-xf, 0.0, None) / R, -1.0, 1.0))  # the normal's tilt toward the observer
    n = n0[:, None, :] * np.cos(th)[None, :, None] + v[None, None, :] * np.sin(th)[None, :, None]
    mu0, mu = np.clip(n @ sun, 0.0, None), np.sin(th)[None, :]
    shade = np.where(xf[None, :] <= 0.0, 2.0 * L * mu0 / np.maximum(mu0 + mu, 1e-9) + (1.0 - L) * mu0, 0.0)
    prof = gaussian_filter1d(shade, sigma / SHADE_FINE, axis=1, mode="nearest")
    return np.array([np.interp(xs, xf, p) for p in prof])


@dataclass(frozen=True)
class RayShading:
    r"""A uniform disc's shading along the rays, for :func:`trace_limb`'s flatness test (step 3) on a dark limb.

    Why: near zero phase a Lambert limb is dark and its radiance rises inward as ``sqrt(2u/R)`` (``mu0 ~ mu`` at depth
    ``u``), so the 2-5 px window inside the foot spans a factor ~1.6 and fails the flatness test on every ray of a
    uniform disc: a mottled Lambert Earth at 2 deg phase (``benchmarks/earth_mottled.py``) kept 2 of 323 rays, its
    limb was not recognised as patchy, and the one-albedo profile answered 1.27 px off (NEES 12).  Divided by the
    shading a uniform ray is flat again, and a cloud edge inside the window is not.  The model is
    :func:`_shaded_rows` (lunar-Lambert ``L``; ``psf_sigma_px`` need not be the frame's: the window is 2-5 px deep,
    where the blur hardly changes the shape), aligned on the trace's reference ellipse."""

    cam: object
    sun_dir_camera: tuple
    L: float = 0.0
    psf_sigma_px: float = 1.0

    def rows(self, ell: tuple, angles: np.ndarray, xs: np.ndarray) -> np.ndarray:
        """The model's radiance on each ray (``angles`` about ``ell``'s centre) at ``xs`` px outward from ``ell``,
        blurred by the PSF and the pixel."""
        return _shaded_rows(_limb_normals(self.cam, ell, angles), self.sun_dir_camera, float(ell[1][0]),
                            _pixel_blur(self.psf_sigma_px), self.L, xs)

    def dark_share(self, ell: tuple, angles: np.ndarray, depths: tuple[float, float] = (0.5, 4.0),
                   flat_frac: float = 0.35) -> float:
        """The share of the rays ``angles`` about ``ell`` on which the uniform disc's own shading, unblurred, fails
        the plain flatness test (range over ``depths`` px inside the limb -- about the trace's window, 2-5 px inside
        a foot 1-2 px outside the limb -- above ``flat_frac`` of the mean): how much of a low keep rate the shading
        explains."""
        xs = np.array([-depths[1], -depths[0]])
        m = _shaded_rows(_limb_normals(self.cam, ell, angles), self.sun_dir_camera, float(ell[1][0]), SHADE_FINE,
                         self.L, xs)
        return float(np.mean(np.abs(m[:, 0] - m[:, 1]) > flat_frac * 0.5 * (m[:, 0] + m[:, 1])))


def shading_offsets(tr: TracedLimb, ell: tuple, cam, sun_dir_camera, psf_sigma_px: float, L: float = 0.0,
                    search: float = 6.0, step: float = 0.5) -> np.ndarray:
    r"""Per ray of ``tr``, where :func:`trace_limb`'s half-level crossing lies (px, outward positive) on a disc of
    *uniform* albedo (lunar-Lambert shading, ``L = 0``: Lambert), blurred by a Gaussian PSF of ``psf_sigma_px`` and
    the pixel: the crossing's photometric bias, which an albedo that varies from ray to ray scales but does not move.

    Why: the shading rises inward from the limb (``mu0 ~ sin(a) cos(psi) + cos(a) sqrt(2u/R)`` at depth ``u``, phase
    ``a``, position angle ``psi`` from the Sun), so the inside level ``P`` 2-5 px deep exceeds the limb's own radiance,
    most toward the horns; the crossings sit up to ~1 PSF sigma inside the limb there and less at the sub-solar point,
    and the ellipse through them moves toward the Sun (``benchmarks/families.py`` Earth ``lambert`` frames traced
    about their true ellipse: +0.15 to +0.37 px along the Sun, 0.00-0.01 px across).  Each ray's model is sampled
    like the ray (``step`` px over ``+-search``), scaled to the ray's inside level, and put through the trace's own
    edge rule (:func:`_ray_edges`, flatness not tested: the ray passed it).  NaN where ``tr`` rejected the ray."""
    xs = np.arange(-search, search + 0.5 * step, step)
    sel = np.ones_like(tr.ok)  # every ray (rejected ones get NaN rows)
    rows = _scaled_rows(tr, sel, ell, _limb_normals(cam, ell, tr.angles), sun_dir_camera, psf_sigma_px, L, xs)
    with np.errstate(all="ignore"):
        r_edge, _, _ = _ray_edges(rows, np.broadcast_to(xs, rows.shape), 0.0, tr.noise, step, np.inf)
    return np.where(tr.ok, r_edge, np.nan)


def _scaled_rows(tr: TracedLimb, sel: np.ndarray, ell: tuple, normals: tuple, sun_dir_camera, psf_sigma_px: float,
                 L: float, xs: np.ndarray) -> np.ndarray:
    """:func:`_shaded_rows` for the rays ``sel`` of ``tr`` (their :func:`_limb_normals` ``normals``; PSF and pixel
    blur), each scaled so that its level about the trace's window (2-5 px inside the foot, ~1 sigma outside the limb)
    is the ray's inside level ``P - s`` (NaN rows where ``tr`` has no level)."""
    sigma = _pixel_blur(psf_sigma_px)
    rows = _shaded_rows(normals, sun_dir_camera, float(ell[1][0]), sigma, L, xs)
    ref = np.median(rows[:, (xs >= -5.0 - sigma) & (xs <= -2.0 - sigma)], axis=1)
    with np.errstate(all="ignore"):
        gain = np.where(ref > 0, (tr.inside[sel] - tr.sky) / ref, np.nan)
    return rows * gain[:, None]


SHADE_SIGMAS = tuple(round(0.4 + 0.1 * i, 1) for i in range(13))
"""The PSF sigmas (px) :func:`shading_sigma` chooses from."""


def _shape_misfit(y: np.ndarray, rel: np.ndarray, rows: np.ndarray, xs: np.ndarray, noise: float) -> float:
    """Mean square between the rays' level-normalised samples ``y`` at ``rel`` (px from each ray's crossing) and the
    shading model ``rows`` (DN above the sky on grid ``xs``, limb at 0) put through the same edge rule, normalised by
    its own inside level and aligned on its own crossing."""
    step = float(xs[1] - xs[0])
    with np.errstate(all="ignore"):
        em, Pm, _ = _ray_edges(rows, np.broadcast_to(xs, rows.shape), 0.0, noise, step, np.inf)
        m = np.array([np.interp(rel[j] + em[j], xs, rows[j] / Pm[j]) for j in range(rows.shape[0])])
    w = (rel >= -5.0) & (rel <= 3.0) & np.isfinite(y) & np.isfinite(m)
    return float(np.mean((y - m)[w] ** 2)) if w.any() else math.inf


def shading_sigma(img: np.ndarray, tr: TracedLimb, ell: tuple, cam, sun_dir_camera, L: float = 0.0,
                  sigmas: tuple[float, ...] = SHADE_SIGMAS, search: float = 6.0) -> float:
    """The PSF sigma (px, from ``sigmas``) whose shading model (:func:`shading_offsets`) best matches the kept rays'
    level-normalised profiles about their own crossings (5 px inside to 3 px outside).  ``L`` is given, not
    chosen: the flatness test keeps the rays whose albedo falls inward, and their profiles look flatter than the
    shading (on the Lambert ``clouds`` frames of ``benchmarks/families.py`` the best ``L`` was 0.25-1.0; on the
    uniform ``lambert`` and lunar-Lambert ``own`` frames it was found, 0 and 0.25-0.75)."""
    ok = tr.ok
    if ok.sum() < 20:
        raise TooManyOutliersError(f"the limb trace kept {int(ok.sum())} rays with a limb against the sky (need >= 20)")
    ang = tr.angles[ok]
    v, rad, _ = _sample_rays(img, ell, ang, search, 0.5)
    r_obs = np.linalg.norm(tr.points[ok] - np.asarray(ell[0], float)[None, :], axis=1)
    y, rel = (v - tr.sky) / (tr.inside[ok] - tr.sky)[:, None], rad - r_obs[:, None]
    xs = np.arange(-search - 4.0, search + 4.25, 0.25)
    normals = _limb_normals(cam, ell, ang)  # (the same for every sigma)
    cost = [_shape_misfit(y, rel, _scaled_rows(tr, ok, ell, normals, sun_dir_camera, sg, L, xs), xs, tr.noise)
            for sg in sigmas]
    return float(sigmas[int(np.argmin(cost))])


def shading_corrected(tr: TracedLimb, offsets: np.ndarray) -> TracedLimb:
    """``tr`` with each kept ray's limb point moved back along its ray by its :func:`shading_offsets` (rays whose
    offset is not finite left out)."""
    u = np.column_stack([np.sin(tr.angles), np.cos(tr.angles)])
    pts = tr.points - np.where(np.isfinite(offsets), offsets, np.nan)[:, None] * u
    inside = np.where(np.isfinite(offsets), tr.inside, np.nan)
    albedo = None if tr.albedo is None else np.where(np.isfinite(offsets), tr.albedo, np.nan)
    return replace(tr, points=pts, inside=inside, albedo=albedo)


def fit_traced(tr: TracedLimb, ell: tuple, free_shape: bool = False) -> tuple:
    """The ellipse through the traced points: ``(r0, c0, a)`` (and ``rho, theta`` when ``free_shape``) by a
    soft-L1 geometric fit (scale 0.5 px), started at ``ell``; returns ``((r0, c0), (a, b), theta)``.  With
    ``tr.glow_term`` (known shape only) the points' residuals include the glow's lift ``g / A_ray``
    (:func:`glow_lift_column`, :func:`fit_traced_glow`)."""
    from scipy.optimize import least_squares

    pts = tr.points[tr.ok]
    if pts.shape[0] < 20:
        raise TooManyOutliersError(f"the limb trace kept {pts.shape[0]} rays with a limb against the sky (need >= 20)")
    if tr.glow_term and not free_shape:
        return fit_traced_glow(tr, ell)[0]
    (r0, c0), (a, b), th = ell

    def shape(x):
        rho, t = (x[3], x[4]) if free_shape else (b / a, th)
        return ((x[0], x[1]), (x[2], x[2] * rho), t)

    x0 = [r0, c0, a] + ([b / a, th] if free_shape else [])
    res = least_squares(lambda x: _band_signed(pts, shape(x)), x0, loss="soft_l1", f_scale=0.5, x_scale="jac")
    (r, c), (aa, bb), t = shape(res.x)
    return ((float(r), float(c)), (float(aa), float(bb)), float(t))


GLOW_LIFT_Z = 4.0
"""The z-score (cluster-robust, :func:`fit_traced_glow`) above which a patchy limb's traced points are fitted with
the glow's lift.  Measured on ``benchmarks/families.py``'s Earth frames (truth ellipse as the trace's reference):
``combined`` (clouds + a glow of 0.05-0.34 of the surface) z = -0.4, 3.3, 4.4, 7.2, 28, 76 (the one at -0.4 the
faintest glow, 0.05); ``clouds`` (no glow) frames 0-16 of seed 2026 z = -2.8 ... 3.2, all below 4."""


def glow_lift_column(tr: TracedLimb) -> np.ndarray:
    """Per kept ray, ``1 / (P - sky)`` over its median: the shape of the outward lift of a ray's half-level crossing
    by a glow above the limb.  A glow adds radiance ``g(x)`` of its own (the same in DN along the limb: it does not
    depend on the surface's albedo) to a step of height ``A = P - sky``; the crossing of ``sky + A/2`` moves out by
    ``g / |I'| ~ sqrt(2 pi) sigma g / A`` (first order), so a ray over ocean (``A`` ten times smaller than over a
    cloud) is lifted ten times more.  Along a cloudy limb ``1/A`` varies by an order of magnitude, so the lift is
    not the radius's constant and is estimated beside the ellipse (on a uniform limb it would be)."""
    inv = 1.0 / np.maximum(tr.inside[tr.ok] - tr.sky, 1e-12)
    return inv / float(np.median(inv))


def glow_lift_columns(tr: TracedLimb, tilt: bool = True) -> np.ndarray:
    """``(n_kept, k)``: :func:`glow_lift_column`, and with ``tilt`` (and ``tr.glow_tilt``, ``tr.lit_angle`` known) the
    same times ``cos psi``, ``psi`` the ray's angle from the lit side's direction: a glow lit by the Sun is brighter
    toward it, ``g (1 + t cos psi)`` (the profile's ``glow_tilt``, :mod:`jaxlimb.models.lunar_lambert`), and lifts the
    sunward rays more, which moves the ellipse toward the Sun.  The tilt is nearly a centre shift along the Sun (the
    two differ only by ``1 / A_ray``), so it is not fitted (:func:`fit_traced_glow`): it is marginalised in the
    covariance (:func:`trace_model_cov`).

    Why: on the full-disc Earth with clouds and a glow (``benchmarks/earth_full_disc.py`` ``combined``, held-out
    seed 2027) the uniform lift left two frames 0.54 and 0.56 px off, both along the Sun's image direction, at centre
    sigmas of 0.08 px (NEES 49 and 14); with the tilt marginalised, NEES 2.4 and 1.1.  Fitting the tilt instead put
    them 0.09 px off and into a typed failure, but moved ``benchmarks/families.py``'s gibbous ``combined`` frames 2-4
    from 0.09 / 0.20 / 0.32 px to 0.48 / 0.38 / 0.50 px.  The pipeline asks for the tilt near zero phase only
    (:data:`jaxlimb.pipeline.ellipsoid.GLOW_TILT_MAX_PHASE_DEG`)."""
    col = glow_lift_column(tr)
    if not (tilt and tr.glow_tilt) or tr.lit_angle is None:
        return col[:, None]
    return np.column_stack([col, col * np.cos(tr.angles[tr.ok] - tr.lit_angle)])


def _glow_residuals(tr: TracedLimb, ell: tuple, tilt: bool):
    pts, cols = tr.points[tr.ok], glow_lift_columns(tr, tilt)
    (_, _), (a, b), th = ell

    def res(x):
        return _band_signed(pts, ((x[0], x[1]), (x[2], x[2] * b / a), th)) - cols @ x[3:]

    return res


def fit_traced_glow(tr: TracedLimb, ell: tuple) -> tuple[tuple, float, float]:
    """The known-shape ellipse through the traced points with the glow's lift ``c / A_ray`` (:func:`glow_lift_column`)
    fitted beside ``(r0, c0, a)`` (soft-L1, as :func:`fit_traced`); returns the ellipse, ``c`` (px at the median ray)
    and its z-score with the cluster-robust sigma of :func:`trace_model_cov` (10 deg clusters, CR2)."""
    from scipy.optimize import least_squares

    if int(tr.ok.sum()) < 20:
        n = int(tr.ok.sum())
        raise TooManyOutliersError(f"the limb trace kept {n} rays with a limb against the sky (need >= 20)")
    (r0, c0), (a, b), th = ell
    res = _glow_residuals(tr, ell, tilt=False)
    x = least_squares(res, [r0, c0, a, 0.0], loss="soft_l1", f_scale=0.5, x_scale="jac").x
    C = _cluster_cov(tr, res, x, 10.0, True)
    z = float(x[3] / math.sqrt(C[3, 3])) if C[3, 3] > 0 else 0.0
    return ((float(x[0]), float(x[1])), (float(x[2]), float(x[2] * b / a)), th), float(x[3]), z


def _cluster_cov(tr: TracedLimb, res, x0: np.ndarray, bin_deg: float, bias_reduced: bool) -> np.ndarray:
    """Cluster-robust covariance of the parameters ``x0`` of the residuals ``res`` of the kept rays (clusters of
    ``bin_deg`` of ray angle); central-difference Jacobian."""
    t = tr.angles[tr.ok]
    r = res(x0)
    J = numerical_jacobian(res, x0, 1e-3)
    groups = np.floor((t - t.min()) / math.radians(bin_deg)).astype(int)
    return (cluster_robust_bias_reduced if bias_reduced else cluster_robust_covariance)(J, r, groups)


def trace_model_cov(tr: TracedLimb, ell: tuple, bin_deg: float = 10.0, bias_reduced: bool = True) -> np.ndarray:
    """Model error of an albedo-patchy limb: the cluster-robust (sandwich) covariance of ``(r0, c0, a)`` of the
    geometric fit of the traced points about ``ell``, clusters of ``bin_deg`` of ray angle.  Albedo structure
    across the limb (a cloud edge 0-2 px inside it) shifts the edge of whole stretches of rays alike; the
    pixel noise of the band fit does not see that, the spread of those stretches does.  ``(3, 3)``.

    The bias-reduced sandwich (CR2, :func:`~jaxlimb.analysis.model_error.cluster_robust_bias_reduced`), not the
    plain one: when few rays survive (a glow and motion blur over clouds, ``benchmarks/families.py`` Earth
    ``combined`` 2: 42 of 1208 rays in 6 sectors, the end sectors' leverage 0.9) the plain sandwich's centre
    sigma was 0.04 px for a 0.19 px error (NEES 14.7); with many well-spread sectors the two agree within 10-40 %.
    ``bias_reduced=False``: the plain sandwich (CR1), the gate of :func:`~jaxlimb.pipeline.ellipsoid._patchy_geometry`
    (tuned with it; its choice between the band fit and the rays is left as it was)."""
    (r0, c0), (a, b), th = ell
    if tr.glow_term:  # the lift (and its tilt) beside the ellipse: their uncertainty is the ellipse's too (marginal)
        res = _glow_residuals(tr, ell, tilt=True)
        from scipy.optimize import least_squares

        k = glow_lift_columns(tr).shape[1]
        c = least_squares(lambda y: res(np.concatenate([[r0, c0, a], y])), [0.0] * k, loss="soft_l1", f_scale=0.5).x
        return _cluster_cov(tr, res, np.concatenate([[r0, c0, a], c]), bin_deg, bias_reduced)[:3, :3]
    pts = tr.points[tr.ok]

    def d(x):
        return _band_signed(pts, ((x[0], x[1]), (x[2], x[2] * b / a), th))

    return _cluster_cov(tr, d, np.array([r0, c0, a], float), bin_deg, bias_reduced)


def coherent_shift_var(tr: TracedLimb, ell: tuple, bin_deg: float = 10.0, min_rays: int = 3) -> float:
    """Variance (px^2, per axis) of the centre shift an albedo-patchy limb's bias field hides in the fit.

    Clouds within a pixel of the limb move whole stretches of traced rays alike (``bin_deg`` sectors of
    ``benchmarks/families.py``'s Earth ``clouds`` frames: -0.8 to +0.6 px).  The known-shape fit absorbs the part
    of that field that looks like a radius (``k = 0``) or a centre shift (``k = 1``), so neither the residuals nor
    their cluster sandwich (:func:`trace_model_cov`) can see it; they see the rest.  With no preferred
    harmonic in an albedo field, the absorbed shift has the visible part's power: the sector means of the rays'
    distances from ``ell`` less their fit by ``1, cos psi, sin psi`` (and the glow's lift, :func:`glow_lift_column`,
    when ``tr.glow_term``) have mean square ``m^2`` of which the rays' own scatter contributes ``var(d) / n_sector``, and
    ``m^2 - var(d)/n`` per axis is the hidden shift's variance.  Measured on held-out ``clouds`` frame 6
    (40 000 km, 602 px): the ellipse 0.63 px off along the direction the sandwich gave 0.14 px (NEES 18); this
    term is 0.28 px, and as a floor on the centre's variance (``ellipsoid_profile._with_trace_error``) it brings the
    NEES to 4.8, while the other near cloudy frames' go 0.3-1.3 -> 0.3-0.5 (frames 0-13,
    ``benchmarks/results/families_earth_clouds14.json``)."""
    ok = tr.ok
    if int(ok.sum()) < 20:
        return 0.0
    psi = tr.angles[ok]
    d = _band_signed(tr.points[ok], ell)
    cols = [np.ones_like(psi), np.cos(psi), np.sin(psi)] + ([glow_lift_column(tr)] if tr.glow_term else [])
    A = np.column_stack(cols)  # what the fit absorbs (radius, centre, a glow's lift): the visible field is the rest
    d = d - A @ np.linalg.lstsq(A, d, rcond=None)[0]
    g = np.floor((psi - psi.min()) / math.radians(bin_deg)).astype(int)
    counts = np.bincount(g)
    sums = np.bincount(g, weights=d)
    use = counts >= min_rays
    if use.sum() < 2:
        return 0.0
    means = sums[use] / counts[use]
    return max(float(np.mean(means**2) - np.mean(np.var(d) / counts[use])), 0.0)


def normalised_band(img: np.ndarray, pts: np.ndarray, tr: TracedLimb) -> tuple[np.ndarray, FitData]:
    """The band's pixels with their ray's levels (module docstring): a keep mask over ``pts`` and the
    :class:`FitData` of the kept pixels (``z_n``, weights, ``offset = sky``, ``scale = C_ref``)."""
    z = np.asarray(img[pts[:, 0].astype(int), pts[:, 1].astype(int)], float)
    ang = np.arctan2(pts[:, 0] - tr.center_rc[0], pts[:, 1] - tr.center_rc[1])
    order = np.argsort(np.mod(tr.angles, 2 * np.pi))
    a_sorted = np.mod(tr.angles, 2 * np.pi)[order]
    idx = np.clip(np.searchsorted(a_sorted, np.mod(ang, 2 * np.pi)), 0, a_sorted.size - 1)
    prev = np.clip(idx - 1, 0, a_sorted.size - 1)
    near = np.where(np.abs(a_sorted[prev] - np.mod(ang, 2 * np.pi)) < np.abs(a_sorted[idx] - np.mod(ang, 2 * np.pi)),
                    prev, idx)
    P = tr.inside[order][near]
    keep = np.isfinite(P)
    c = P[keep] - tr.sky
    cref = float(np.median(c)) if c.size else 1.0
    return keep, FitData(pts[keep], (z[keep] - tr.sky) / c, c / cref, tr.sky, cref)


__all__ = ["GLOW_LIFT_Z", "TracedLimb", "coherent_shift_var", "fit_traced", "fit_traced_glow", "glow_lift_column",
           "glow_lift_columns", "normalised_band", "trace_limb", "trace_model_cov"]
