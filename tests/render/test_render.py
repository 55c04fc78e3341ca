"""Tests of the truth renderer (jaxlimb.render): geometry vs the limb cone, flux, cropping, noise, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jaxlimb.errors import ConfigError, GeometryError, LimbInputError
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.conic import conic_eval, ellipse_to_conic
from jaxlimb.geometry.ellipsoid import image_conic
from jaxlimb.render import (
    AlbedoPatches,
    Atmosphere,
    RenderOptions,
    Scene,
    earth_scene,
    lattice_offsets,
    lunar_lambert_L,
    moon_scene,
    pixel_rays,
    reflectance,
    render_body,
    render_radiance,
    trace_rays,
)
from jaxlimb.render.validate import limb_accuracy, limb_strip_errors

MOON = 1737.4
# a 300 x 400 crop far from the optical axis of a 16 mm / 2.2 um camera (off-axis perspective)
CAM_OFF = Camera(rows=300, cols=400, principal_point_rc=(-700.0, -900.0))
CAM_SMALL = Camera(rows=300, cols=400)


def _ellipsoid_scene(cam=CAM_OFF, rc=(140.0, 210.0), dist=3000.0, sun=None):
    R = Rotation.from_euler("zyx", [0.3, 0.5, -0.2]).as_matrix()
    return Scene(
        radii=(60.0, 45.0, 40.0),
        center_cam=tuple(cam.los(np.array(rc)) * dist),
        R_body_to_camera=R,
        sun_dir_cam=sun,
    )


# ------------------------------------------------------------------------------ truth
def test_moon_scene_truth():
    cam = Camera()
    sc = moon_scene(60000.0, 40.0, center_rc=(800.0, 1500.0), camera=cam, sun_angle_deg=30.0)
    img, tr = render_body(sc, cam, RenderOptions(), seed=3)
    assert img.shape == (1944, 2592) and img.dtype == np.uint16
    assert tr.center_rc == pytest.approx((800.0, 1500.0), abs=1e-9)
    assert tr.range_km == pytest.approx(60000.0)
    assert tr.phase_angle_deg == pytest.approx(40.0, abs=1e-9)
    assert tr.apparent_radius_px == pytest.approx(cam.focal_px * MOON / math.sqrt(60000.0**2 - MOON**2))
    assert np.linalg.norm(tr.sun_dir_cam) == pytest.approx(1.0)
    assert tr.crop == "none"
    assert tr.limb.semi_axes_px[0] == pytest.approx(tr.apparent_radius_px, rel=2e-3)
    assert tr.cone_rho == pytest.approx(1.0) and tr.gamma_off_rad == pytest.approx(0.0, abs=1e-9)
    # the lit side lies toward the position angle 30 deg: (d_row, d_col) = (-sin 30, cos 30)
    f = img.astype(float) - np.median(img)
    rr, cc = np.nonzero(f > 0.5 * f.max())
    v = np.array([rr.mean() - 800.0, cc.mean() - 1500.0])
    ang = math.degrees(math.atan2(-v[0], v[1]))
    assert ang == pytest.approx(30.0, abs=2.0)
    d = tr.as_dict()
    assert d["center_rc"] == pytest.approx([800.0, 1500.0]) and d["ellipse"]["semi_axes_px"][0] > 0


# ------------------------------------------------------------------------------ limb vs cone
@pytest.mark.parametrize("which", ["sphere", "ellipsoid"])
def test_rendered_limb_matches_image_conic(which):
    """Eq. (2) image conic vs the ray-traced, supersampled limb: <= 0.02 px.

    Strip integrals of the coverage (tests/render/_limb_metrics.py) give the mean limb
    position in every usable row/column on both sides; we require the mean of each side
    (centre and size) within 0.005 px and the per-strip RMS within 0.02 px.
    """
    if which == "sphere":
        sc = moon_scene(MOON * 145.0, 0.0, center_rc=(150.0, 200.0), camera=CAM_OFF)
    else:
        sc = _ellipsoid_scene()
    win = render_radiance(sc, CAM_OFF, "uniform", n_subsamples=89)
    L = win.limb
    assert L.center_offset_px > 0.05  # the off-axis ellipse centre is not the projected centre
    acc = limb_accuracy(win)
    assert acc["n_strips"] > 300
    assert acc["rms_px"] < 0.02, acc
    for side in ("left_px", "right_px", "top_px", "bottom_px"):
        assert abs(acc[side]) < 0.005, acc
    e = limb_strip_errors(win.image, L.conic, row0=win.row0, col0=win.col0)
    assert float(np.sqrt(np.mean(e**2))) == pytest.approx(acc["rms_px"], rel=1e-12)
    # negative controls: the measurement detects a 0.02 px shift of the conic, or a 0.02 px larger ellipse
    (r0, c0), (a, b), th = L.center_rc, L.semi_axes_px, L.angle_rad
    shifted = limb_accuracy(win, ellipse_to_conic((r0 + 0.02, c0 - 0.02), (a, b), th))
    assert abs(shifted["top_px"]) > 0.015 and abs(shifted["left_px"]) > 0.015
    bigger = limb_accuracy(win, ellipse_to_conic((r0, c0), (a + 0.02, b + 0.02), th))
    assert bigger["right_px"] - bigger["left_px"] < -0.03


@settings(max_examples=8, deadline=None)
@given(
    euler=st.tuples(*[st.floats(-math.pi, math.pi)] * 3),
    axes=st.tuples(st.floats(15.0, 38.0), st.floats(0.6, 1.0), st.floats(0.5, 1.0)),
    rc=st.tuples(st.floats(120.0, 180.0), st.floats(150.0, 250.0)),
)
def test_rendered_limb_matches_image_conic_random_poses(euler, axes, rc):
    """Property: for random triaxial ellipsoids and poses, the rendered limb sits on the Eq. (2) conic."""
    a = axes[0]
    radii = (a, a * axes[1], a * axes[1] * axes[2])
    R = Rotation.from_euler("zyx", euler).as_matrix()
    sc = Scene(radii=radii, center_cam=tuple(CAM_OFF.los(np.array(rc)) * 3000.0), R_body_to_camera=R, sun_dir_cam=None)
    win = render_radiance(sc, CAM_OFF, "uniform", n_subsamples=89)
    rmin, rmax, cmin, cmax = win.limb.bbox_rc()
    assert rmin > 0 and cmin > 0 and rmax < 299 and cmax < 399  # whole disk in the frame
    acc = limb_accuracy(win)
    assert acc["n_strips"] > 100
    assert acc["rms_px"] < 0.02, acc
    for side in ("left_px", "right_px", "top_px", "bottom_px"):
        assert abs(acc[side]) < 0.006, acc


def test_disk_area_and_centroid_match_the_conic():
    """Area of the uniform disk = pi a b; its centroid is the ellipse centre, not the projected centre."""
    sc = moon_scene(MOON * 145.0, 0.0, center_rc=(150.0, 200.0), camera=CAM_OFF)
    win = render_radiance(sc, CAM_OFF, "uniform", n_subsamples=89)
    L = win.limb
    area = win.image.sum()
    assert area == pytest.approx(math.pi * L.semi_axes_px[0] * L.semi_axes_px[1], rel=2e-5)
    rows = win.row0 + np.arange(win.image.shape[0])
    cols = win.col0 + np.arange(win.image.shape[1])
    cr = float((win.image.sum(axis=1) * rows).sum() / area)
    ccol = float((win.image.sum(axis=0) * cols).sum() / area)
    assert math.hypot(cr - L.center_rc[0], ccol - L.center_rc[1]) < 0.01
    assert L.center_offset_px > 0.06


def test_corner_offset_about_one_pixel():
    """Default imager, sphere of ~180 px radius near the corner: ellipse centre ~1 px from the body centre."""
    cam = Camera()
    sc = moon_scene(70000.0, 30.0, center_rc=(190.0, 200.0), camera=cam)
    tr = render_body(sc, cam, RenderOptions.noiseless(psf_sigma_px=0.0, n_subsamples=21), seed=0)[1]
    assert tr.center_rc == pytest.approx((190.0, 200.0), abs=1e-9)
    assert 0.7 < tr.limb.center_offset_px < 1.5
    # the offset points away from the principal point (perspective stretch)
    v = np.subtract(tr.limb.center_rc, tr.center_rc)
    w = np.subtract(tr.center_rc, cam.principal_point_rc)
    assert v @ w > 0


def test_flux_conservation_supersampling_and_psf():
    sc = moon_scene(MOON * 200.0, 50.0, center_rc=(150.0, 200.0), camera=CAM_SMALL, sun_angle_deg=70.0)
    tot = {}
    for n in (1, 21, 89, 233):
        tot[n] = render_radiance(sc, CAM_SMALL, "lommel-seeliger", n_subsamples=n).image.sum()
    assert tot[89] == pytest.approx(tot[233], rel=1e-4)
    assert tot[21] == pytest.approx(tot[233], rel=1e-3)
    assert tot[1] == pytest.approx(tot[233], rel=2e-2)
    # the PSF moves flux but conserves it (body well inside)
    o0 = RenderOptions.noiseless(psf_sigma_px=0.0, exposure_e=1000.0)
    o2 = RenderOptions.noiseless(psf_sigma_px=2.0, exposure_e=1000.0)
    a = render_body(sc, CAM_SMALL, o0, seed=1)[0]
    b = render_body(sc, CAM_SMALL, o2, seed=1)[0]
    assert b.sum() == pytest.approx(a.sum(), rel=1e-9)
    assert a.sum() == pytest.approx(1000.0 * tot[89], rel=1e-12)
    assert b.max() < a.max()


def test_lattice_is_n_rooks_and_centered():
    for n in (1, 13, 21, 64, 89):
        o = lattice_offsets(n)
        assert o.shape == (n, 2)
        assert np.all(np.abs(o) < 0.5)
        assert np.allclose(o.mean(axis=0), 0.0, atol=1e-12)
        for k in range(2):
            assert np.allclose(np.sort(o[:, k]), (np.arange(n) + 0.5) / n - 0.5)
    with pytest.raises(ConfigError):
        lattice_offsets(0)


# ------------------------------------------------------------------------------ cropping
def test_cropped_frame_equals_subwindow_of_larger_frame():
    """A body cut by the frame renders exactly as the same pixels of a larger frame (PSF included)."""
    big = Camera(rows=400, cols=500, principal_point_rc=(260.0, 300.0))
    small = Camera(rows=200, cols=300, principal_point_rc=(160.0, 200.0))  # pixel (i, j) = big (i+100, j+100)
    q = big.los(np.array([140.0, 150.0])) * (MOON * 150.0)
    sc = Scene(radii=(MOON,) * 3, center_cam=tuple(q), sun_dir_cam=(0.6, -0.3, -0.74))
    opt = RenderOptions.noiseless(psf_sigma_px=1.5, exposure_e=1000.0, n_stars=0)
    a, ta = render_body(sc, small, opt, seed=0)
    b, tb = render_body(sc, big, opt, seed=0)
    assert ta.crop == "partial" and tb.crop == "none"
    assert np.allclose(a, b[100:300, 100:400], rtol=0, atol=1e-9 * b.max())
    assert a.max() > 100


def test_body_fully_outside_the_frame():
    cam = CAM_SMALL
    sc = moon_scene(MOON * 300.0, 20.0, center_rc=(-200.0, 600.0), camera=cam)
    img, tr = render_body(sc, cam, RenderOptions(bit_depth=12, background_e=50.0, read_noise_e=0.0), seed=2)
    assert tr.crop == "outside"
    assert tr.center_rc[0] == pytest.approx(-200.0)
    gain = tr.gain_e_per_dn
    assert abs(img.astype(float).mean() - 50.0 / gain) < 0.05 * 50.0 / gain + 0.5


# ------------------------------------------------------------------------------ terminator
def test_terminator_zero_crossing_lies_on_the_terminator_conic():
    """Bisection of mu0 = 0 along rows with the ray tracer lands on the terminator conic."""
    cam = CAM_SMALL
    sc = _ellipsoid_scene(cam=cam, rc=(150.0, 200.0), dist=1200.0, sun=(0.7, -0.2, -0.5))
    tr = render_body(sc, cam, RenderOptions.noiseless(psf_sigma_px=0.0, n_subsamples=13), seed=0)[1]
    C = tr.terminator.conic
    assert C is not None
    L = tr.limb
    rmin, rmax, cmin, cmax = L.bbox_rc()
    n_found = 0
    for r in np.linspace(rmin + 3, rmax - 3, 25):
        cs = np.linspace(cmin, cmax, 400)
        d = pixel_rays(cam, np.column_stack([np.full_like(cs, r), cs]))
        h = trace_rays(sc, d)
        lit = h.hit & (h.mu0 > 0)
        dark = h.hit & (h.mu0 <= 0)
        idx = np.nonzero((lit[:-1] & dark[1:]) | (dark[:-1] & lit[1:]))[0]
        for i in idx:
            lo, hi = cs[i], cs[i + 1]
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                hm = trace_rays(sc, pixel_rays(cam, np.array([[r, mid]])))
                hl = trace_rays(sc, pixel_rays(cam, np.array([[r, lo]])))
                if (hm.mu0[0] > 0) == (hl.mu0[0] > 0):
                    lo = mid
                else:
                    hi = mid
            pt = np.array([r, 0.5 * (lo + hi)])
            v = conic_eval(C, pt)
            g = abs(conic_eval(C, pt + [0.0, 1e-3]) - conic_eval(C, pt - [0.0, 1e-3])) / 2e-3
            assert abs(v) / g < 1e-6
            n_found += 1
    assert n_found >= 15


@pytest.mark.parametrize("body", ["moon", "triaxial"])
def test_rendered_lit_unlit_boundary_lies_on_the_terminator(body):
    """Pixels where the rendered (Lambert, sharp) image turns dark are within ~1 px of the terminator curve."""
    cam = CAM_SMALL
    if body == "moon":
        sc = moon_scene(MOON * 160.0, 100.0, center_rc=(150.0, 200.0), camera=cam, sun_angle_deg=20.0)
    else:
        sc = _ellipsoid_scene(cam=cam, rc=(150.0, 200.0), dist=1200.0, sun=(0.7, -0.2, -0.5))
    win = render_radiance(sc, cam, "lambert", n_subsamples=21)
    tr = render_body(sc, cam, RenderOptions.noiseless(psf_sigma_px=0.0, reflectance="lambert"), seed=0)[1]
    img = win.image
    rows = win.row0 + np.arange(img.shape[0])
    cols = win.col0 + np.arange(img.shape[1])
    RR, CC = np.meshgrid(rows, cols, indexing="ij")
    L = tr.limb
    deep = L.evaluate(np.stack([RR, CC], -1)) < 0
    # stay 3 px inside the limb
    deep &= np.abs(conic_eval(L.conic, np.stack([RR, CC], -1))) > 3 * 2 * np.abs(L.conic[:2, :2]).max() * L.semi_axes_px[0]
    lit = img > 0
    b = np.zeros_like(lit)
    b[:, 1:] |= lit[:, 1:] & ~lit[:, :-1] & deep[:, 1:] & deep[:, :-1]
    b[:, :-1] |= lit[:, :-1] & ~lit[:, 1:] & deep[:, 1:] & deep[:, :-1]
    pts = np.stack([RR[b], CC[b]], -1)
    assert len(pts) > 30
    curve = tr.terminator.visible_points_rc(20000)
    dmin = np.min(np.linalg.norm(pts[:, None, :] - curve[None, :, :], axis=-1), axis=1)
    assert dmin.max() < 1.0


# ------------------------------------------------------------------------------ photometry
def test_reflectance_models():
    mu0 = np.array([1.0, 0.5, 0.2, -0.1])
    mu = np.array([1.0, 0.5, 0.9, 0.5])
    assert np.allclose(reflectance("lambert", mu0, mu, 0.0), [1.0, 0.5, 0.2, 0.0])
    assert np.allclose(reflectance("lommel-seeliger", mu0, mu, 0.0), [1.0, 1.0, 0.4 / 1.1, 0.0])
    assert np.allclose(reflectance("lunar-lambert", mu0, mu, 0.0), reflectance("lommel-seeliger", mu0, mu, 0.0))
    a = math.radians(60.0)
    L = float(lunar_lambert_L(a))
    assert L == pytest.approx(1 - 0.019 * 60 + 2.42e-4 * 3600 - 1.46e-6 * 216000)
    assert np.allclose(
        reflectance("lunar-lambert", mu0, mu, a),
        L * reflectance("lommel-seeliger", mu0, mu, 0.0) + (1 - L) * reflectance("lambert", mu0, mu, 0.0),
    )
    assert np.allclose(reflectance("uniform", mu0, mu, 0.0), 1.0)
    with pytest.raises(ConfigError):
        reflectance("phong", mu0, mu, 0.0)


def test_shading_matches_the_formula_at_pixel_centers():
    """Non-supersampled pixels hold exactly the reflectance at the pixel-centre ray."""
    sc = moon_scene(MOON * 300.0, 70.0, camera=CAM_SMALL, sun_angle_deg=200.0)
    for model in ("lommel-seeliger", "lunar-lambert", "lambert"):
        win = render_radiance(sc, CAM_SMALL, model, 21)
        sel = (win.image > 0) & ~win.supersampled
        ii, jj = np.nonzero(sel)
        rc = np.stack([ii + win.row0, jj + win.col0], -1).astype(float)
        h = trace_rays(sc, pixel_rays(CAM_SMALL, rc))
        assert np.all(h.hit)
        ref = reflectance(model, h.mu0, h.mu, h.alpha)
        assert np.allclose(win.image[sel], ref, rtol=1e-12, atol=1e-14)
        assert len(ii) > 500


def test_full_moon_lommel_seeliger_is_flat_lambert_is_darkened():
    sc = moon_scene(MOON * 400.0, 0.0, camera=CAM_SMALL)
    ls = render_radiance(sc, CAM_SMALL, "lommel-seeliger", 21)
    lb = render_radiance(sc, CAM_SMALL, "lambert", 21)
    interior = (ls.image > 0) & ~ls.supersampled
    # no limb darkening at zero phase (up to the ~R/D perspective difference between mu and mu0)
    assert np.allclose(ls.image[interior], 1.0, atol=5e-3)
    c = lb.image.shape[0] // 2, lb.image.shape[1] // 2
    assert lb.image[c] == pytest.approx(1.0, abs=1e-3)
    assert lb.image[interior].min() < 0.5


def test_albedo_patches_seeded():
    sc1 = moon_scene(MOON * 300.0, 30.0, camera=CAM_SMALL, albedo_patches=AlbedoPatches(seed=1, amplitude=0.2))
    sc1b = moon_scene(MOON * 300.0, 30.0, camera=CAM_SMALL, albedo_patches=AlbedoPatches(seed=1, amplitude=0.2))
    sc2 = moon_scene(MOON * 300.0, 30.0, camera=CAM_SMALL, albedo_patches=AlbedoPatches(seed=2, amplitude=0.2))
    a = render_radiance(sc1, CAM_SMALL, "lambert", 13).image
    b = render_radiance(sc1b, CAM_SMALL, "lambert", 13).image
    c = render_radiance(sc2, CAM_SMALL, "lambert", 13).image
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    # texture look-up vs the exact field
    p = AlbedoPatches(seed=4, amplitude=0.3)
    x = np.random.default_rng(0).normal(size=(500, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    assert np.allclose(p.factor(x), p.factor_exact(x), atol=5e-3)
    assert 0.1 < np.std(p.factor_exact(x)) < 0.5


# ------------------------------------------------------------------------------ Earth
def test_earth_scene_ellipse_and_atmosphere():
    cam = Camera(rows=200, cols=300)
    atm = Atmosphere(height_km=100.0, scale_height_km=8.0, brightness=0.5)
    # Earth centre far right of this small frame: its left limb (radius ~1175 px) crosses the frame
    sc = earth_scene(40000.0, 35.0, 40.0, center_rc=(100.0, 1400.0), camera=cam, atmosphere=atm)
    tr = render_body(sc, cam, RenderOptions.noiseless(psf_sigma_px=0.0, reflectance="lambert", exposure_e=1.0), seed=0)[1]
    L = tr.limb
    assert tr.crop == "partial"
    # north up -> the polar (minor) axis is vertical, the major axis horizontal (angle 0 or pi)
    assert min(L.angle_rad, math.pi - L.angle_rad) < 1e-3
    assert L.rho < 0.999
    assert tr.cone_rho < 0.999  # Eq. 9 (the image ratio differs off-axis: perspective stretch)
    assert tr.gamma_off_rad > 0
    assert tr.limb.center_offset_px > 0
    # glow: decreasing with height outside the limb, absent beyond the shell top
    win = render_radiance(sc, cam, "lambert", 13)
    cols = win.col0 + np.arange(win.image.shape[1])
    prof = win.image[100 - win.row0]
    # left limb on row 100 from the conic
    C = L.conic
    A, B, Cc = C[0, 0], 2 * (C[0, 1] * 100.0 + C[0, 2]), C[1, 1] * 1e4 + 2 * C[1, 2] * 100.0 + C[2, 2]
    c_edge = (-B - math.sqrt(B * B - 4 * A * Cc)) / (2 * A)
    km_per_px = tr.range_km / cam.focal_px
    h_km = (c_edge - cols) * km_per_px  # approximate tangent altitude of each pixel's ray
    out = (h_km > 8.0) & (h_km < 95.0)  # beyond the supersampled edge pixels
    vals = prof[out]
    assert np.all(np.diff(vals) >= -1e-12)  # increasing toward the limb (cols increase)
    assert vals[-1] > 0.2 * atm.brightness
    expected = atm.brightness * np.exp(-h_km[out] / atm.scale_height_km)
    assert np.allclose(vals, expected, rtol=0.1, atol=0.002)
    assert np.all(prof[h_km > 110.0] == 0.0)
    assert tr.atmosphere_limb is not None and tr.atmosphere_limb.semi_axes_px[0] > L.semi_axes_px[0]


# ------------------------------------------------------------------------------ sensor
def test_reproducible_with_seed_and_noise_level():
    sc = moon_scene(MOON * 300.0, 30.0, camera=CAM_SMALL)
    opt = RenderOptions(background_e=100.0, read_noise_e=5.0, n_stars=5, n_hot_pixels=3, bit_depth=16,
                        gain_e_per_dn=1.0)
    a, ta = render_body(sc, CAM_SMALL, opt, seed=11)
    b, tb = render_body(sc, CAM_SMALL, opt, seed=11)
    c, _ = render_body(sc, CAM_SMALL, opt, seed=12)
    assert np.array_equal(a, b) and np.array_equal(ta.stars_rc, tb.stars_rc)
    assert not np.array_equal(a, c)
    # background region: Poisson(100) + read noise 5 e- (gain 1) -> std ~ sqrt(125)
    corner = a[:40, :40].astype(float)
    mask = np.ones_like(corner, bool)
    for r, cc in ta.hot_pixels_rc:
        if r < 40 and cc < 40:
            mask[r, cc] = False
    for (r, cc) in ta.stars_rc:
        if r < 48 and cc < 48:
            mask[max(0, int(r) - 6): int(r) + 7, max(0, int(cc) - 6): int(cc) + 7] = False
    if mask.sum() > 500:
        assert corner[mask].mean() == pytest.approx(100.0, abs=2.0)
        assert corner[mask].std() == pytest.approx(math.sqrt(125.0), rel=0.15)


def test_quantisation_and_saturation():
    sc = moon_scene(MOON * 300.0, 30.0, camera=CAM_SMALL)
    img8, t8 = render_body(sc, CAM_SMALL, RenderOptions(bit_depth=8, exposure_e=1e6), seed=0)
    assert img8.dtype == np.uint8 and img8.max() == 255
    img12, _ = render_body(sc, CAM_SMALL, RenderOptions(bit_depth=12), seed=0)
    assert img12.dtype == np.uint16 and 0.7 * 4095 < img12.max() <= 4095
    img16, _ = render_body(sc, CAM_SMALL, RenderOptions(bit_depth=16), seed=0)
    assert img16.dtype == np.uint16 and img16.max() > 40000
    f, _ = render_body(sc, CAM_SMALL, RenderOptions.noiseless(), seed=0)
    assert f.dtype == np.float64
    assert f.max() == pytest.approx(0.8 * 20000.0, rel=1e-9)  # auto exposure


def test_stars_and_hot_pixels():
    cam = CAM_SMALL
    sc = moon_scene(MOON * 150.0, 30.0, camera=cam)
    opt = RenderOptions.noiseless(psf_sigma_px=1.0, exposure_e=0.0, n_stars=60, n_hot_pixels=7,
                                  star_flux_e=(1000.0, 1000.0), hot_pixel_e=(5e4, 5e4))
    img, tr = render_body(sc, cam, opt, seed=5)
    assert len(tr.stars_rc) == 60 and len(tr.hot_pixels_rc) == 7
    on_disk = tr.limb.evaluate(tr.stars_rc) < 0
    assert np.array_equal(tr.stars_visible, ~on_disk)
    assert 0 < on_disk.sum() < 60
    hot = np.zeros(img.shape, bool)
    hot[tr.hot_pixels_rc[:, 0], tr.hot_pixels_rc[:, 1]] = True
    assert np.all(img[hot] >= 5e4)
    total = img.sum() - 7 * 5e4
    inside = ((tr.stars_rc[:, 0] > 5) & (tr.stars_rc[:, 0] < 294) & (tr.stars_rc[:, 1] > 5) & (tr.stars_rc[:, 1] < 394))
    n_vis_in = int(np.sum(tr.stars_visible & inside))
    n_vis_edge = int(np.sum(tr.stars_visible & ~inside))
    assert n_vis_in * 1000.0 - 1e-6 <= total <= (n_vis_in + n_vis_edge) * 1000.0 + 1e-6


# ------------------------------------------------------------------------------ errors
def test_bad_inputs_raise_typed_errors():
    cam = CAM_SMALL
    with pytest.raises(GeometryError):
        moon_scene(1000.0, 30.0, camera=cam)  # inside the Moon
    with pytest.raises(ConfigError):
        moon_scene(1e5, 190.0, camera=cam)
    with pytest.raises(ConfigError):
        moon_scene(-5.0, 10.0, camera=cam)
    with pytest.raises(GeometryError):
        Scene(radii=(1.0, 0.0, 1.0), center_cam=(0, 0, 100.0))
    with pytest.raises(GeometryError):
        Scene(radii=(1.0, 1.0, 1.0), center_cam=(0, 0, -100.0))
    with pytest.raises(GeometryError):
        Scene(radii=(10.0, 10.0, 10.0), center_cam=(0, 0, 5.0))
    with pytest.raises(LimbInputError):
        Scene(radii=(1.0, 1.0, 1.0), center_cam=(0, 0, 100.0), sun_dir_cam=(0, 0, 0))
    with pytest.raises(LimbInputError):
        Scene(radii=(1.0, 1.0, 1.0), center_cam=(0, 0, 100.0), R_body_to_camera=np.ones((3, 3)))
    for kw in (dict(bit_depth=10), dict(psf_sigma_px=-1.0), dict(n_subsamples=0), dict(reflectance="mirror"),
               dict(full_well_e=0.0), dict(n_stars=-1), dict(star_flux_e=(5.0, 1.0)), dict(read_noise_e=np.nan)):
        with pytest.raises(ConfigError):
            RenderOptions(**kw)
    sc = moon_scene(1e5, 30.0, camera=cam)
    with pytest.raises(ConfigError):
        render_body(sc, cam, RenderOptions(), seed=-1)
    with pytest.raises(ConfigError):
        render_body("moon", cam)  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        render_radiance(Scene(radii=(MOON,) * 3, center_cam=(0, 0, 1e5), sun_dir_cam=None), cam, "lambert", 5)
    with pytest.raises(ConfigError):
        AlbedoPatches(amplitude=-1.0)
    with pytest.raises(ConfigError):
        Atmosphere(height_km=0.0)
    with pytest.raises(GeometryError):
        image_conic(cam, MOON, [0.0, 0.0, 1000.0])
