"""The limb traced against the sky (jaxlimb.pipeline.ellipsoid.trace) on synthetic discs with known limbs."""

from __future__ import annotations

import jax
import numpy as np
from scipy.ndimage import gaussian_filter

from jaxlimb.geometry.conic import ellipse_signed_distance
from jaxlimb.pipeline.ellipsoid.patchy import GLOW_TILT_MAX_PHASE_DEG, _asymmetry, _fit_rays, _glow_tilt
from jaxlimb.pipeline.ellipsoid.trace import trace_limb
from jaxlimb.pipeline.ellipsoid.trace_fit import (coherent_shift_var, fit_traced, glow_lift_columns, normalised_band,
                                                  trace_model_cov)
from jaxlimb.pipeline import covariance_block


def _disc(patchy: bool, seed: int = 0):
    """A blurred disc of radius 150 px at (200.3, 210.7) on a dark sky; ``patchy``: the inside level jumps tenfold
    between 20-deg sectors and a bright 'cloud' ring lies 8-14 px inside the limb."""
    rng = np.random.default_rng(seed)
    r0, c0, R = 200.3, 210.7, 150.0
    y, x = np.mgrid[0:400, 0:420].astype(float)
    sub = 4  # supersampled edge
    ys, xs = np.mgrid[0:400 * sub, 0:420 * sub].astype(float) / sub - (sub - 1) / (2 * sub)
    d = np.hypot(ys - r0, xs - c0)
    lev = np.full(d.shape, 100.0)
    if patchy:
        ang = np.degrees(np.arctan2(ys - r0, xs - c0)) % 360
        lev = np.where((ang // 20) % 2 == 0, 100.0, 10.0)
        lev = np.where((d > R - 14) & (d < R - 8), 400.0, lev)
    img = np.where(d <= R, lev, 0.0).reshape(400, sub, 420, sub).mean(axis=(1, 3))
    img = gaussian_filter(img, 0.8) + rng.normal(0, 0.5, img.shape)
    del x, y
    return img, ((r0, c0), (R, R), 0.0)


def test_uniform_disc_traced_on_its_limb():
    img, truth = _disc(False)
    start = ((truth[0][0] + 6.0, truth[0][1] - 5.0), (156.0, 156.0), 0.0)
    tr = trace_limb(img, start, (1.0, 0.0), np.radians(60.0), 20.0)
    # the flat-inside window (2-5 px inside the 5-sigma foot) still holds the top of a sharp edge's rise on many
    # rays, which are left out (a conservative choice: deeper windows let cloud edges in, benchmarks/families.py)
    assert tr.ok.sum() > 30 and not tr.patchy()
    assert np.median(np.abs(ellipse_signed_distance(tr.points[tr.ok], truth))) < 0.1
    e = fit_traced(tr, start)
    assert np.hypot(e[0][0] - truth[0][0], e[0][1] - truth[0][1]) < 0.05 and abs(e[1][0] - 150.0) < 0.05


def test_patchy_disc_outermost_edge_not_the_inner_ring():
    """The bright ring inside the limb is four times the limb's contrast: the trace keeps the outer edge, flags
    the limb as patchy, and the per-ray levels put every kept ray's inside at 1."""
    img, truth = _disc(True)
    start = ((truth[0][0] + 6.0, truth[0][1] - 5.0), (156.0, 156.0), 0.0)
    tr = trace_limb(img, start, (1.0, 0.0), np.radians(60.0), 20.0)
    assert tr.patchy()
    assert np.max(np.abs(ellipse_signed_distance(tr.points[tr.ok], truth))) < 0.5
    e = fit_traced(tr, start)
    assert np.hypot(e[0][0] - truth[0][0], e[0][1] - truth[0][1]) < 0.1
    pts = tr.points[tr.ok] - 3.0 * (tr.points[tr.ok] - np.array(tr.center_rc)) / 150.0  # 3 px inside the limb
    keep, fd = normalised_band(img, np.round(pts), tr)
    assert keep.mean() > 0.9 and abs(np.median(fd.z) - 1.0) < 0.1


def test_step_asymmetry_witness_sees_a_one_sided_glow():
    """``ellipsoid._asymmetry``: on a uniform blurred disc the ellipses through the 30 % and 70 % crossings share
    their centre (only the radius moves, by the step's width); a glow above one half of the lit arc raises the
    30 % crossings there and not the 70 % ones, and the centres part."""

    img, truth = _disc(False)
    lit, half = (0.0, 1.0), np.radians(60.0)
    d0 = _asymmetry(img, truth, lit, half)
    r0, c0 = truth[0]
    y, x = np.mgrid[0:400, 0:420].astype(float)
    rr = np.hypot(y - r0, x - c0)
    glow = np.where((rr > 150.0) & (y < r0) & (x > c0), 30.0 * np.exp(-(rr - 150.0) / 1.5), 0.0)
    d1 = _asymmetry(img + gaussian_filter(glow, 0.8), truth, lit, half)
    assert d0 is not None and d1 is not None
    assert np.hypot(d0[0], d0[1]) < 0.03 and d0[2] == 0.0
    assert np.hypot(d1[0], d1[1]) > 0.1


def _glow_disc(glow_dn: float, seed: int, tilt: float = 0.0):
    """A disc whose lit arc is bright (100) on one half and alternates bright/dim (10) in 10-deg sectors on the
    other, with an exponential glow of ``glow_dn`` at the limb (1.5 px scale) outside it: the same DN over dim and
    bright sectors, as a glow above a cloudy Earth; ``tilt``: the glow is ``1 + tilt cos psi`` times brighter, ``psi``
    the angle from +row (the lit direction of the tests)."""
    rng = np.random.default_rng(seed)
    r0, c0, R, sub = 200.3, 210.7, 150.0, 4
    ys, xs = np.mgrid[0:400 * sub, 0:420 * sub].astype(float) / sub - (sub - 1) / (2 * sub)
    d = np.hypot(ys - r0, xs - c0)
    ang_rad = np.arctan2(ys - r0, xs - c0)
    ang = np.degrees(ang_rad) % 360
    lev = np.where((ang < 90) | ((ang // 10) % 2 == 0), 100.0, 10.0)
    glow = glow_dn * (1.0 + tilt * np.cos(ang_rad - np.pi / 2)) * np.exp(-(d - R) / 1.5)
    img = np.where(d <= R, lev, glow).reshape(400, sub, 420, sub).mean(axis=(1, 3))
    return gaussian_filter(img, 0.8) + rng.normal(0, 0.5, img.shape), ((r0, c0), (R, R), 0.0)


def test_glow_lift_fitted_on_a_patchy_limb():
    """A glow lifts the half-level crossings of the dim rays ten times more than the bright ones': the plain ray fit
    is pulled 0.57 px toward the dim half; ``ellipsoid._fit_rays`` finds the lift (z ~ 10) and fits it beside the
    ellipse (centre within 0.14 px, radius within 0.11 px).  Without a glow the gate stays shut."""

    for seed in (0, 1):
        img, truth = _glow_disc(5.0, seed)
        tr = trace_limb(img, truth, (1.0, 0.0), np.radians(60.0), 12.0)
        plain = fit_traced(tr, truth)
        tr2, e = _fit_rays(tr, truth)
        assert tr2.glow_term and not tr.glow_term
        assert np.hypot(plain[0][0] - truth[0][0], plain[0][1] - truth[0][1]) > 0.4
        assert np.hypot(e[0][0] - truth[0][0], e[0][1] - truth[0][1]) < 0.2 and abs(e[1][0] - 150.0) < 0.15
        img0, _ = _glow_disc(0.0, seed)
        assert not _fit_rays(trace_limb(img0, truth, (1.0, 0.0), np.radians(60.0), 12.0), truth)[0].glow_term


def test_glow_tilt_toward_the_sun_is_in_the_covariance():
    """A glow brighter toward the Sun (``1 + cos psi``, as a shell lit by it) lifts the sunward rays more: the uniform
    lift's ellipse is 0.3-0.9 px off along the lit direction, which the lift alone cannot see (NEES 16 and 192 with
    its cluster sandwich).  ``trace_model_cov`` marginalises the lift's tilt too (``glow_lift_columns``): the same
    errors are inside their sigmas (NEES below 1); the tilt is too weakly measured on a patchy arc to be corrected
    (fitted, it moved ``benchmarks/families.py``'s Earth ``combined`` 2 from 0.09 to 0.48 px), so only its
    uncertainty is carried (the pipeline asks for it near zero phase, ``ellipsoid.GLOW_TILT_MAX_PHASE_DEG``).  Without
    ``glow_tilt`` the trace keeps the uniform lift alone."""
    from dataclasses import replace


    for seed in (0, 2):
        img, truth = _glow_disc(5.0 / 1.5, seed, tilt=1.0)
        tr, e = _fit_rays(trace_limb(img, truth, (1.0, 0.0), np.radians(60.0), 12.0), truth, glow_tilt=True)
        assert tr.glow_term and tr.glow_tilt and abs(tr.lit_angle - np.pi / 2) < 1e-12
        d = np.array([e[0][0] - truth[0][0], e[0][1] - truth[0][1]])
        assert 0.25 < abs(d[0]) < 1.0 and abs(d[1]) < 0.1
        nees = [float(d @ np.linalg.solve(trace_model_cov(t, e)[:2, :2], d))
                for t in (tr, replace(tr, glow_tilt=False))]
        assert nees[0] < 1.0 < 10.0 < nees[1]
        assert glow_lift_columns(replace(tr, glow_tilt=False)).shape[1] == 1 and glow_lift_columns(tr).shape[1] == 2


def _traced(bias, noise: float, seed: int = 0):
    """A :class:`TracedLimb` on a 600 px circle's 130-deg arc, one ray per 0.1 deg: each ray's point moved
    outward by ``bias(psi)`` plus white noise of ``noise`` px."""
    from jaxlimb.pipeline.ellipsoid.trace import TracedLimb

    rng = np.random.default_rng(seed)
    c, R = np.array([700.0, 1100.0]), 600.0
    psi = np.radians(np.arange(60.0, 190.0, 0.1))
    rad = R + bias(psi) + rng.normal(0.0, noise, psi.size)
    pts = c + rad[:, None] * np.column_stack([np.sin(psi), np.cos(psi)])
    tr = TracedLimb(tuple(c), psi, pts, np.full(psi.size, 100.0), 0.0, 1.0)
    return tr, ((c[0], c[1]), (R, R), 0.0)


def test_coherent_shift_var_sees_a_coherent_bias_field_not_white_noise():
    """``coherent_shift_var``: white per-ray noise (0.3 px) gives a hidden-shift variance near 0, and so does a field the
    fit absorbs (a radius and a centre shift: ``1, cos psi, sin psi``); a bias field coherent over 40 deg of arc
    (+-0.3 px, the albedo stretches of a cloudy limb) gives about its own mean square."""

    tr, ell = _traced(lambda p: 0.0 * p, 0.3)
    assert coherent_shift_var(tr, ell) < 0.01**2 * 4
    tr, ell = _traced(lambda p: 0.3 + 0.5 * np.cos(p) + 0.2 * np.sin(p), 0.3)
    assert coherent_shift_var(tr, ell) < 0.01**2 * 4
    tr, ell = _traced(lambda p: 0.3 * np.sign(np.sin(p * 4.5)), 0.3)
    v = coherent_shift_var(tr, ell)
    assert 0.2**2 < v < 0.35**2


def test_fit_traced_moves_a_centre_far_from_the_origin():
    """At a 2000 px centre the ellipse frame in float32 (1e-4 px resolution) swallowed the finite-difference steps
    of the soft-L1 fit: its centre never left the start (a far cloudy Earth, ``benchmarks/families.py`` Earth
    ``clouds`` 3, stayed on a front-end circle 4 px off).  ``_band_signed`` is float64 now, whatever JAX's x64 flag."""
    from jaxlimb.pipeline.ellipsoid.trace import TracedLimb

    truth = ((1697.46, 2097.64), (124.03, 122.42), 2.4)
    t = np.linspace(-1.4, 1.4, 200) + 0.6
    ct, st = np.cos(truth[2]), np.sin(truth[2])
    x, y = truth[1][0] * np.cos(t), truth[1][1] * np.sin(t)
    pts = np.column_stack([truth[0][0] - x * st - y * ct, truth[0][1] + x * ct - y * st])  # Eq. 20
    tr = TracedLimb((1694.9, 2093.4), t, pts, np.full(t.size, 100.0), 0.0, 1.0)
    start = ((1694.9, 2093.4), (121.5, 121.5 * truth[1][1] / truth[1][0]), truth[2])
    shifted = ((truth[0][0] + 1e-6, truth[0][1]), truth[1], truth[2])
    with jax.enable_x64(False):  # a library user who did not enable x64 (the CLI and the benchmarks do)
        assert np.max(np.abs(ellipse_signed_distance(pts, truth))) < 1e-9
        assert np.all(ellipse_signed_distance(pts, shifted) != ellipse_signed_distance(pts, truth))  # resolves a micro-pixel step
        e = fit_traced(tr, start)
    assert np.hypot(e[0][0] - truth[0][0], e[0][1] - truth[0][1]) < 1e-3 and abs(e[1][0] - truth[1][0]) < 1e-3


def test_shading_offsets_remove_the_lambert_limbs_pull_toward_the_sun():
    """A uniform Lambert Earth (the project's renderer, PSF sigma 0.9 px, 40 deg phase, a 420 x 420 frame at 300 000 km, 155 px):
    the half-level crossings of the traced rays sit inside the limb by more toward the horns than at the sub-solar
    point, so the ellipse through them moves toward the Sun; the shading model (its PSF sigma chosen from the rays'
    profiles) takes that back."""
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging.prior import sun_direction_image
    from jaxlimb.pipeline.ellipsoid.trace import shading_corrected, shading_offsets, shading_sigma
    from jaxlimb.render import RenderOptions, earth_scene, render_body

    cam = Camera(focal_length_mm=16.0, rows=420, cols=420)
    sc = earth_scene(300000.0, 20.0, 40.0, center_rc=(208.3, 211.6), camera=cam, sun_angle_deg=30.0)
    img, truth = render_body(sc, cam, RenderOptions(reflectance="lambert", psf_sigma_px=0.9, bit_depth=12, extra_noise_dn=60.0), seed=3)
    ell = (tuple(truth.limb.center_rc), tuple(truth.limb.semi_axes_px), truth.limb.angle_rad)
    sd = np.asarray(sun_direction_image(truth.sun_dir_cam, cam, ell[0]))
    tr = trace_limb(np.asarray(img, float), ell, tuple(sd), np.radians(80.0), 6.0)

    def along_sun(e):
        return float((np.array(e[0]) - np.array(ell[0])) @ sd)

    plain = along_sun(fit_traced(tr, ell))
    sig = shading_sigma(np.asarray(img, float), tr, ell, cam, truth.sun_dir_cam)
    fixed = along_sun(fit_traced(shading_corrected(tr, shading_offsets(tr, ell, cam, truth.sun_dir_cam, sig)), ell))
    assert abs(sig - 0.9) <= 0.1
    assert plain > 0.2 and abs(fixed) < 0.05, (plain, fixed, sig)  # measured 0.329 -> -0.006 px, sigma 0.9


def _lambert_earth_2deg(patches):
    """A Lambert Earth near zero phase (2 deg, the project's renderer; 420 x 420 at 300 000 km, 155 px, PSF 0.9 px):
    its limb is dark and brightens inward as ``sqrt(2u/R)``.  ``patches``: an ``AlbedoPatches`` or ``None``."""
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging.prior import sun_direction_image
    from jaxlimb.render import RenderOptions, earth_scene, render_body

    cam = Camera(focal_length_mm=16.0, rows=420, cols=420)
    sc = earth_scene(300000.0, 20.0, 2.0, center_rc=(208.3, 211.6), camera=cam, sun_angle_deg=30.0,
                     albedo_patches=patches)
    img, truth = render_body(sc, cam, RenderOptions(reflectance="lambert", psf_sigma_px=0.9, bit_depth=12,
                                                    extra_noise_dn=20.0), seed=3)
    ell = (tuple(truth.limb.center_rc), tuple(truth.limb.semi_axes_px), truth.limb.angle_rad)
    sd = tuple(np.asarray(sun_direction_image(truth.sun_dir_cam, cam, ell[0])))
    return np.asarray(img, float), ell, sd, cam, truth, sc


def test_shading_flattened_trace_keeps_a_dark_limbs_rays_and_tells_mottled_from_uniform():
    """Near zero phase every ray of a uniform Lambert limb fails the plain flatness test (its 2-5 px window rises by a
    factor ~1.6); divided by the uniform disc's shading (``RayShading``) the rays are kept, and the albedo they then
    carry is level on the uniform disc and not on a mottled one (``AlbedoPatches`` amplitude 0.6).  Measured: plain
    0 and 2 of 323 rays kept; flattened 322 and 322; albedo RMS 0.015 and 0.083."""
    from jaxlimb.pipeline.ellipsoid.trace import RayShading
    from jaxlimb.render.scene import AlbedoPatches

    for patches, patchy in ((None, False), (AlbedoPatches(seed=4, amplitude=0.6), True)):
        img, ell, sd, cam, truth, _ = _lambert_earth_2deg(patches)
        half = np.radians(60.0)
        plain = trace_limb(img, ell, sd, half, 6.0)
        flat = trace_limb(img, ell, sd, half, 6.0, shade=RayShading(cam, tuple(truth.sun_dir_cam), 0.0))
        assert plain.ok.mean() < 0.05 and flat.ok.mean() > 0.9, (plain.ok.sum(), flat.ok.sum())
        assert flat.patchy() is patchy
        # the crossings' shading bias is ~0.7 px (shading_offsets takes it out)
        assert np.median(np.abs(ellipse_signed_distance(flat.points[flat.ok], ell))) < 1.5


def test_mottled_lambert_earth_near_zero_phase_measured_with_an_honest_covariance():
    """``locate`` (attitude known) on the mottled Lambert Earth at 2 deg phase: before the shading-flattened trace it
    answered 1.27 px off with centre sigmas 0.22 / 0.38 px (NEES 12); measured now 0.088 px, NEES 0.24
    (``benchmarks/earth_mottled.py``)."""
    from jaxlimb.pipeline import locate
    from jaxlimb.render.scene import AlbedoPatches

    img, ell, sd, cam, truth, sc = _lambert_earth_2deg(AlbedoPatches(seed=4, amplitude=0.6))
    hints = {"body": "earth", "range_prior_km": 1.01 * truth.range_km, "sun_dir_camera": list(truth.sun_dir_cam),
             "R_body_to_camera": np.asarray(sc.R_body_to_camera).tolist()}
    m = locate(img, cam, hints)
    err = np.subtract(m.center_rc, truth.center_rc)
    c = m.covariance
    P = covariance_block(c)
    assert m.extras["profile_rejected"] is not None  # the one-albedo profile is not this limb's
    assert np.hypot(*err) < 0.25 and float(err @ np.linalg.solve(P, err)) < 4.0, (err, P)


def test_albedo_patchy_weighs_the_albedo_field_against_the_ray_noise():
    """A flattened trace's albedo (log) along 240 rays over 120 deg: an albedo field of four cycles along the arc
    (RMS 0.088 after the second-order harmonic fit) over ray noise of 0.030 is patchy -- as ``earth_mottled.py`` map 9
    at 2 deg, 0.080 over 0.033, which three times the noise called uniform -- and ray noise of 0.05 alone (RMS above
    PATCHY_ALBEDO_TOL) is not."""
    from jaxlimb.pipeline.ellipsoid.trace import _albedo_patchy

    rng = np.random.default_rng(5)
    t = np.linspace(-np.radians(60.0), np.radians(60.0), 240)
    field = 0.12 * np.sin(12.0 * t + 0.3)
    assert _albedo_patchy(t, field + rng.normal(0.0, 0.03, t.size))
    assert not _albedo_patchy(t, rng.normal(0.0, 0.05, t.size))
    assert not _albedo_patchy(t, 0.2 * np.cos(t) + rng.normal(0.0, 0.01, t.size))  # a smooth fade is no albedo map


def test_dark_share_opens_the_flattened_trace_only_near_zero_phase():
    """``RayShading.dark_share``: the share of the lit window's rays on which a uniform Lambert disc fails the plain
    flatness test by its shading alone -- all of them at 2 deg of phase, none at 40 deg (where a low keep rate comes
    from clouds, glows or smear, and flattening moved ``families.py`` Earth ``combined`` 2 from 0.09 to 1.32 px)."""
    import math

    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging.prior import sun_direction_image
    from jaxlimb.pipeline.ellipsoid.trace import RayShading
    from jaxlimb.render import RenderOptions, earth_scene, render_body

    cam = Camera(focal_length_mm=16.0, rows=420, cols=420)
    share = {}
    for phase in (2.0, 40.0):
        sc = earth_scene(300000.0, 20.0, phase, center_rc=(208.3, 211.6), camera=cam, sun_angle_deg=30.0)
        _, truth = render_body(sc, cam, RenderOptions(reflectance="lambert", psf_sigma_px=0.9), seed=3)
        ell = (tuple(truth.limb.center_rc), tuple(truth.limb.semi_axes_px), truth.limb.angle_rad)
        sd = np.asarray(sun_direction_image(truth.sun_dir_cam, cam, ell[0]))
        angles = math.atan2(sd[0], sd[1]) + np.linspace(-np.radians(60.0), np.radians(60.0), 120)
        share[phase] = RayShading(cam, tuple(truth.sun_dir_cam)).dark_share(ell, angles)
    assert share[2.0] == 1.0 and share[40.0] == 0.0, share


def test_wide_trace_retraces_a_dark_limb_about_the_rays_own_fit():
    """The flattened trace's shading is placed on its reference ellipse: about the front end's ellipse of the mottled
    Lambert Earth at 10 deg of phase (``benchmarks/earth_mottled.py`` map 15; 0.7 px off, the radius 1.1 px short) it
    kept fewer rays than the plain trace, the plain one stood, the limb was not flagged patchy and the one-albedo
    profile answered 1.09 px off (NEES 5.5).  ``wide_trace`` now retraces it about the plain rays' own fit."""
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging.prior import sun_direction_image
    from jaxlimb.pipeline.ellipsoid.start import wide_trace
    from jaxlimb.pipeline.ellipsoid.trace import RayShading
    from jaxlimb.render import RenderOptions, earth_scene, render_body
    from jaxlimb.render.scene import AlbedoPatches

    cam = Camera(focal_length_mm=16.0, rows=420, cols=420)
    sc = earth_scene(300000.0, 20.0, 10.0, center_rc=(208.3, 211.6), camera=cam, sun_angle_deg=30.0,
                     albedo_patches=AlbedoPatches(seed=15, amplitude=0.6))
    img, truth = render_body(sc, cam, RenderOptions(reflectance="lambert", psf_sigma_px=0.9, bit_depth=12,
                                                    extra_noise_dn=20.0), seed=3)
    (r0, c0), (a, b), th = truth.limb.center_rc, truth.limb.semi_axes_px, truth.limb.angle_rad
    start = ((r0 + 0.68, c0 + 0.15), (a - 1.13, b - 1.13), th)  # the front end's ellipse on this frame
    sd = tuple(np.asarray(sun_direction_image(truth.sun_dir_cam, cam, start[0])))
    shade = RayShading(cam, tuple(truth.sun_dir_cam), 0.0)
    half, search = np.radians(60.0), max(12.0, 0.2 * start[1][0])
    plain = trace_limb(np.asarray(img, float), start, sd, half, search)
    about_start = trace_limb(np.asarray(img, float), start, sd, half, search, shade=shade)
    tr = wide_trace(np.asarray(img, float), start, sd, half, shade)
    assert about_start.ok.sum() < plain.ok.sum(), (about_start.ok.sum(), plain.ok.sum())  # measured 24 < 55
    assert tr.albedo is not None and tr.ok.sum() > 4 * plain.ok.sum() and tr.patchy(), tr.ok.sum()  # measured 270


def test_glow_tilt_is_asked_for_near_zero_phase_only():
    """``ellipsoid._glow_tilt``: the Sun 12 deg from behind the body on the boresight (the full disc from L1) asks for
    the glow's tilt, 45 deg (a gibbous Earth) does not, and neither does a frame without the Sun."""
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.pipeline.frame import prepare

    cam = Camera(focal_length_mm=16.0, rows=101, cols=121)
    img = np.zeros((101, 121))

    def frame(phase_deg):
        a = np.radians(phase_deg)
        return prepare(img, cam, {"body": "earth", "sun_dir_camera": [np.sin(a), 0.0, -np.cos(a)]}, None)

    assert 12.0 < GLOW_TILT_MAX_PHASE_DEG < 45.0
    c = (50.0, 60.0)  # the boresight
    assert _glow_tilt(frame(12.0), c) and not _glow_tilt(frame(45.0), c)
    assert not _glow_tilt(prepare(img, cam, {"body": "earth"}, None), c)
