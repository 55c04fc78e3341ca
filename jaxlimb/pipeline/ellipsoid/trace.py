r"""The limb as the boundary against space: the outermost edge along rays from the centre (ellipsoid strategy).

A cloudy Earth has interior albedo edges (cloud against ocean: albedo 0.75 against 0.06) as strong as the
limb, and its limb's brightness changes by an order of magnitude along the arc (a cloud over the limb, then
ocean).  A gradient front end takes cloud edges for limb points, and a band fit with one inside level is
pulled by them.  What tells the limb from every cloud edge is that it is the *last* transition before the sky: along
each ray from the centre, outward, nothing brighter than the sky follows it.

:func:`trace_limb` samples rays across the lit window (one per px of arc) from ``search`` px inside to
``search`` px outside the current ellipse and, on each ray,

1. the sky level ``s`` and its noise ``sigma`` (median and MAD of the outer third of all rays' samples);
2. the outermost sample brighter than ``s + 5 sigma`` (the limb's outer foot; nothing brighter lies outside);
3. the inside level ``P``: the median over 2-5 px inside that foot; the ray is kept when ``P - s >= 8 sigma``
   and that interior is flat (range within ``flat_frac (P - s)``: no cloud edge within the band's depth);
4. the limb point: the outermost crossing of ``(s + P) / 2`` (linear interpolation), the 50 % point of a
   symmetric blurred step (the edge models' convention, :mod:`jaxlimb.pipeline.ellipsoid`).

:func:`fit_traced` fits the ellipse (shape held: ``rho, theta``) to the points with a robust (soft-L1)
geometric cost; :func:`fit_traced_glow` adds a glow's lift of each ray's crossing, ``c / (P_ray - s)``
(:func:`glow_lift_column`), for a glow above a cloudy limb.  The per-ray levels normalise the band's pixels for the edge and profile fits
(:func:`normalised_band`): ``z_n = (z - s) / (P_ray - s)`` with weights ``(P_ray - s) / C_ref`` (as the
sphere's level normalisation, :class:`jaxlimb.pipeline.stages.FitData`), i.e. an inside level that may vary
from ray to ray, and the pixels of rejected rays (faint, or a cloud edge inside the band) left out.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace

import numpy as np

from ...errors import TooManyOutliersError
from ...geometry.conic import ellipse_signed_distance
from .shading import RayShading, limb_normals, pixel_blur, shaded_rows


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
        """Whether the limb's inside level varies along the arc by more than a smooth photometric fade does: the RMS of
        ``log P`` about its second-order harmonic fit in the ray angle exceeds ``tol``.  Lambert-like fading toward the
        horns is a first/second harmonic; an albedo map (clouds over an ocean) is not.  Also patchy: fewer than one ray
        in ten kept when the kept rays' levels are not as level as a uniform disc's (RMS above :data:`FEW_RAYS_RMS`).
        A shading-flattened trace is judged by its rays' albedo instead (:data:`PATCHY_ALBEDO_TOL`).

        Parameters
        ----------
        tol : float
            The largest RMS of ``log P`` of a uniform limb (0.1: 10 %).

        Returns
        -------
        bool
            ``True`` for an albedo-patchy limb; ``False`` also when fewer than 20 rays have a level above the sky.
        """
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
"""RMS (of ``log``) of the albedo along a shading-flattened trace's rays above which the limb is patchy: a uniform
disc keeps it near the ray noise, an albedo map well above it.  Tuned on the mottled Earths of
``benchmarks/earth_mottled.py`` (``docs/validation/constants.md#patchy_albedo_tol``)."""


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
    as much as an albedo map does (``docs/validation/constants.md#patchy_albedo_tol``)."""
    noise = 1.4826 * float(np.median(np.abs(np.diff(y)))) / math.sqrt(2.0)
    return _harmonic_rms(t, y) > max(PATCHY_ALBEDO_TOL, 2.0 * noise)


def _ray_radius(ell: tuple, u: np.ndarray) -> np.ndarray:
    """Distance from the ellipse centre to the ellipse along unit directions ``u`` ``(n, 2)`` (two first-order
    steps of :func:`ellipse_signed_distance`)."""
    c = np.asarray(ell[0], float)
    r = np.full(u.shape[0], float(ell[1][0]))
    for _ in range(3):
        r = r - ellipse_signed_distance(c + r[:, None] * u, ell)
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
    ratio; ``None`` without ``shade_rows``).  The inside level is read below the outer foot, not iterated from the
    half crossing: iterated, it climbs onto cloud edges inside an ocean limb
    (``docs/validation/constants.md#ray-levels``)."""
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
    """Trace the limb along rays across the lit window about ellipse ``ell`` (module docstring, steps 1-4).

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image.
    ell : tuple
        The reference ellipse ``((r0, c0), (a, b), theta)`` (px, rad); rays start at its centre.
    lit_dir : tuple of float or None
        Direction ``(d_row, d_col)`` of the lit side; ``None``: all round.
    half : float
        Half-angle (rad) of the lit window about ``lit_dir``.
    search : float
        How far (px) inside and outside ``ell`` each ray is sampled.
    step : float
        Sample spacing along the rays (px).
    flat_frac : float
        Largest range of the inside window, as a fraction of ``P - s``, of a kept ray.
    level : float
        The crossing's fraction of the step (0.5, the edge; others measure the step's asymmetry).
    shade : RayShading or None
        Test the inside's flatness on the rays divided by a uniform disc's shading (:class:`RayShading`).

    Returns
    -------
    TracedLimb
        Ray angles, limb points ``(row, col)`` and inside levels (NaN on rejected rays), sky level and noise (DN).

    Raises
    ------
    TooManyOutliersError
        No sky outside the limb (every ray leaves the frame).
    """
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


def shading_offsets(tr: TracedLimb, ell: tuple, cam, sun_dir_camera, psf_sigma_px: float, L: float = 0.0,
                    search: float = 6.0, step: float = 0.5) -> np.ndarray:
    """Per ray of ``tr``, where :func:`trace_limb`'s half-level crossing lies on a disc of *uniform* albedo
    (lunar-Lambert shading, ``L = 0``: Lambert), blurred by a Gaussian PSF of ``psf_sigma_px`` and the pixel: the
    crossing's photometric bias, which an albedo that varies from ray to ray scales but does not move.

    Why: the shading rises inward from the limb (``mu0 ~ sin(a) cos(psi) + cos(a) sqrt(2u/R)`` at depth ``u``, phase
    ``a``, position angle ``psi`` from the Sun), so the inside level ``P`` 2-5 px deep exceeds the limb's own radiance,
    most toward the horns; the crossings sit up to ~1 PSF sigma inside the limb there and less at the sub-solar point,
    and the ellipse through them moves toward the Sun.  Each ray's model is sampled like the ray (``step`` px over
    ``+-search``), scaled to the ray's inside level, and put through the trace's own edge rule (flatness not
    tested: the ray passed it).

    Parameters
    ----------
    tr : TracedLimb
        The trace.
    ell : tuple
        Its reference ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    cam : Camera
        The pinhole camera.
    sun_dir_camera : array_like (3,)
        Direction toward the Sun (camera frame).
    psf_sigma_px : float
        The PSF's Gaussian sigma (px; :func:`shading_sigma`).
    L : float
        The lunar-Lambert weight.
    search, step : float
        Sampling of the model rays (px).

    Returns
    -------
    np.ndarray (n,)
        The offsets (px, outward positive); NaN where ``tr`` rejected the ray.
    """
    xs = np.arange(-search, search + 0.5 * step, step)
    sel = np.ones_like(tr.ok)  # every ray (rejected ones get NaN rows)
    rows = _scaled_rows(tr, sel, ell, limb_normals(cam, ell, tr.angles), sun_dir_camera, psf_sigma_px, L, xs)
    with np.errstate(all="ignore"):
        r_edge, _, _ = _ray_edges(rows, np.broadcast_to(xs, rows.shape), 0.0, tr.noise, step, np.inf)
    return np.where(tr.ok, r_edge, np.nan)


def _scaled_rows(tr: TracedLimb, sel: np.ndarray, ell: tuple, normals: tuple, sun_dir_camera, psf_sigma_px: float,
                 L: float, xs: np.ndarray) -> np.ndarray:
    """:func:`shaded_rows` for the rays ``sel`` of ``tr`` (their :func:`limb_normals` ``normals``; PSF and pixel
    blur), each scaled so that its level about the trace's window (2-5 px inside the foot, ~1 sigma outside the limb)
    is the ray's inside level ``P - s`` (NaN rows where ``tr`` has no level)."""
    sigma = pixel_blur(psf_sigma_px)
    rows = shaded_rows(normals, sun_dir_camera, float(ell[1][0]), sigma, L, xs)
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
    shading.

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image.
    tr : TracedLimb
        The trace.
    ell : tuple
        Its reference ellipse ``((r0, c0), (a, b), theta)`` (px, rad).
    cam : Camera
        The pinhole camera.
    sun_dir_camera : array_like (3,)
        Direction toward the Sun (camera frame).
    L : float
        The lunar-Lambert weight.
    sigmas : tuple of float
        The candidate sigmas (px).
    search : float
        Half-length (px) of the rays re-sampled.

    Returns
    -------
    float
        The best sigma (px).

    Raises
    ------
    TooManyOutliersError
        Fewer than 20 kept rays.
    """
    ok = tr.ok
    if ok.sum() < 20:
        raise TooManyOutliersError(f"the limb trace kept {int(ok.sum())} rays with a limb against the sky (need >= 20)")
    ang = tr.angles[ok]
    v, rad, _ = _sample_rays(img, ell, ang, search, 0.5)
    r_obs = np.linalg.norm(tr.points[ok] - np.asarray(ell[0], float)[None, :], axis=1)
    y, rel = (v - tr.sky) / (tr.inside[ok] - tr.sky)[:, None], rad - r_obs[:, None]
    xs = np.arange(-search - 4.0, search + 4.25, 0.25)
    normals = limb_normals(cam, ell, ang)  # (the same for every sigma)
    cost = [_shape_misfit(y, rel, _scaled_rows(tr, ok, ell, normals, sun_dir_camera, sg, L, xs), xs, tr.noise)
            for sg in sigmas]
    return float(sigmas[int(np.argmin(cost))])


def shading_corrected(tr: TracedLimb, offsets: np.ndarray) -> TracedLimb:
    """``tr`` with each kept ray's limb point moved back along its ray by its :func:`shading_offsets` (rays whose
    offset is not finite left out).

    Parameters
    ----------
    tr : TracedLimb
        The trace.
    offsets : np.ndarray (n,)
        Per-ray offsets (px, outward positive).

    Returns
    -------
    TracedLimb
        The corrected trace.
    """
    u = np.column_stack([np.sin(tr.angles), np.cos(tr.angles)])
    pts = tr.points - np.where(np.isfinite(offsets), offsets, np.nan)[:, None] * u
    inside = np.where(np.isfinite(offsets), tr.inside, np.nan)
    albedo = None if tr.albedo is None else np.where(np.isfinite(offsets), tr.albedo, np.nan)
    return replace(tr, points=pts, inside=inside, albedo=albedo)


__all__ = ["TracedLimb", "trace_limb"]
