"""The independent renderer (jaxlimb.render.independent): truth, ray casting, PSFs, glow, and
agreement with the project's own renderer where both model the same thing."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from jaxlimb.geometry.camera import Camera
from jaxlimb.render.independent import (
    Body,
    Glow,
    Photometry,
    Pinhole,
    Psf,
    PsfKind,
    Reflectance,
    Surface,
    earth_case,
    limb_truth,
    moon_case,
    render_radiance,
)
from jaxlimb.render.independent.geometry import closest_approach
from jaxlimb.render.independent.optics import glow_column

CAM = Camera(focal_length_mm=16.0, pixel_pitch_mm=0.0022, rows=300, cols=360)


def _moon_body(center_rc=(140.3, 201.7), range_km=150000.0, phase_deg=40.0):
    from jaxlimb.render import moon_scene

    sc = moon_scene(range_km, phase_deg, center_rc=center_rc, camera=CAM, sun_angle_deg=20.0)
    return sc, Body(sc.radii, np.array(sc.center_cam), np.eye(3), np.array(sc.sun_dir_cam))


def test_truth_matches_the_projects_limb_conic_and_the_ray_cast_coverage():
    """Limb ellipse from the cone vs jaxlimb.geometry's image conic, and vs the area and centroid of
    the ray-cast disc on a 1/8-px grid (an ellipse's centroid is its centre)."""
    from jaxlimb.geometry.ellipsoid import image_conic

    R = np.array([[0.6, -0.8, 0.0], [0.8, 0.6, 0.0], [0.0, 0.0, 1.0]])
    pin = Pinhole.from_camera(CAM)
    q = 200000.0 * pin.los((60.0, 300.0))
    body = Body((3000.0, 2900.0, 2600.0), q, R, np.array([0.0, 0.0, -1.0]))
    t = limb_truth(body, pin)
    ref = image_conic(CAM, np.array((3000.0, 2900.0, 2600.0)), q, R)
    assert np.allclose(t.ellipse_center_rc, ref.center_rc, atol=1e-6)
    assert np.allclose(sorted(t.semi_axes_px), sorted(ref.semi_axes_px), atol=1e-6)
    assert t.body_center_rc == pytest.approx(pin.project(q), abs=1e-9)
    (r, c), (a, b) = t.ellipse_center_rc, t.semi_axes_px
    g = np.arange(-a - 2, a + 2, 0.125)
    rr, cc = np.meshgrid(r + g, c + g, indexing="ij")
    inside = closest_approach(body, pin.directions(rr.ravel(), cc.ravel())) < 1.0
    area = inside.sum() * 0.125**2
    assert area == pytest.approx(math.pi * a * b, rel=2e-3)
    assert rr.ravel()[inside].mean() == pytest.approx(r, abs=0.01)
    assert cc.ravel()[inside].mean() == pytest.approx(c, abs=0.01)


def test_lambert_sphere_matches_the_projects_renderer():
    """Same scene, Lambert, Gaussian PSF 1 px, no noise: the two renderers' images agree to 0.1 %
    of the peak away from the limb, to 1.5 % on it (the project's renderer samples an edge pixel
    89 times, this one 256 times) and their flux centroids to 0.002 px (measured 2.5e-4)."""
    from jaxlimb.render import RenderOptions, render_body

    sc, body = _moon_body()
    img_ref, _ = render_body(sc, CAM, RenderOptions(reflectance="lambert", psf_sigma_px=1.0, bit_depth=None, noise=False,
                                                    exposure_e=1.0, background_e=0.0), seed=0)
    img = render_radiance(body, Surface(Photometry(Reflectance.LAMBERT)), Pinhole.from_camera(CAM), Psf(PsfKind.GAUSSIAN, 1.0))
    a, b = img / img.max(), np.asarray(img_ref) / np.max(img_ref)
    rr, cc = np.mgrid[0:CAM.rows, 0:CAM.cols]
    t = limb_truth(body, Pinhole.from_camera(CAM))
    limb = np.abs(np.hypot(rr - t.ellipse_center_rc[0], cc - t.ellipse_center_rc[1]) - t.semi_axes_px[0]) < 3
    assert np.max(np.abs(a - b)[~limb]) < 1e-3
    assert np.max(np.abs(a - b)[limb]) < 1.5e-2
    for w in (rr, cc):
        assert (w * a).sum() / a.sum() == pytest.approx((w * b).sum() / b.sum(), abs=2e-3)


@pytest.mark.parametrize("psf", [Psf(PsfKind.GAUSSIAN, 0.8), Psf(PsfKind.AIRY, r_zero=1.5), Psf(PsfKind.DEFOCUS, r_disc=1.2),
                                 Psf(PsfKind.MOTION, sigma=0.6, length=3.0, angle_deg=30.0)])
def test_psf_kernels_are_normalised_and_centered(psf):
    K = psf.kernel(4)
    n = K.shape[0]
    c = (np.arange(n) - (n - 1) / 2) / 4
    assert K.sum() == pytest.approx(1.0)
    assert (K.sum(0) * c).sum() == pytest.approx(0.0, abs=1e-12)
    assert (K.sum(1) * c).sum() == pytest.approx(0.0, abs=1e-12)
    if psf.kind is PsfKind.MOTION:  # smeared along its angle: wider along (cos, -sin) than across
        a = math.radians(psf.angle_deg)
        X, Y = np.meshgrid(c, c)
        along = ((X * math.cos(a) - Y * math.sin(a)) ** 2 * K).sum()
        across = ((X * math.sin(a) + Y * math.cos(a)) ** 2 * K).sum()
        assert along > 2 * across


def test_airy_first_dark_ring():
    p = Psf(PsfKind.AIRY, r_zero=1.7)
    assert p._value(np.array([1.7]), np.array([0.0]))[0] < 1e-6
    assert p._value(np.array([0.0]), np.array([0.0]))[0] == pytest.approx(1.0)


@pytest.mark.parametrize("case", [("miss", 6390.0, 0.0), ("graze", 6377.9, None), ("hit", 6000.0, None)])
def test_glow_column_closed_forms_match_quadrature(case):
    _, p, _ = case
    glow = Glow(scale_height_km=10.0, brightness=1.0)
    Rl = 6378.0
    hit = p < Rl
    mu = math.sqrt(1.0 - (p / Rl) ** 2) if hit else 0.0
    col = glow_column(glow, np.array([p]), np.array([Rl]), np.array([mu]), np.array([hit]))[0]
    s0 = math.sqrt(Rl**2 - p**2) if hit else 0.0

    def f(s):
        return math.exp(-(math.hypot(p, s0 + s) - Rl) / 10.0)

    ref = quad(f, 0.0, 3000.0, limit=400, points=[1.0, 10.0, 100.0])[0] * (1 if hit else 2)
    assert col == pytest.approx(ref, rel=0.01)


def test_reflectance_laws_are_dark_on_the_night_side_and_positive_on_the_day_side():
    mu0 = np.array([-0.2, 0.0, 0.3, 0.9])
    mu = np.array([0.5, 0.5, 0.02, 0.9])
    cg = np.full(4, math.cos(0.5))
    for law in Reflectance:
        r = Photometry(law).radiance(mu0, mu, cg)
        assert np.all(r[:2] == 0) and np.all(r[2:] > 0), law


def test_families_render_with_consistent_truth():
    """A quick cropped Moon and a far Earth: the truth's centre is where the image says
    (flux on the lit side of the truth ellipse, nothing far outside it)."""
    c = moon_case("cropped", np.random.default_rng(3))
    (r, cc), a = c.truth.ellipse_center_rc, c.truth.semi_axes_px[0]
    img = c.image.astype(float)
    rr, kk = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    far = np.hypot(rr - r, kk - cc) > a + 15
    assert img[far].mean() < 0.01 * img.max() and img.max() > 100
    e = earth_case("clouds", np.random.default_rng(4), far=True)
    assert e.truth.range_km == pytest.approx(e.meta["range_km"])
    assert e.hints["R_body_to_camera"] is not None and e.image.dtype in (np.uint8, np.uint16)


def test_earth_ablations_keep_every_draw_and_replace_one_component():
    """``earth_case(..., ablate=...)`` (benchmarks/earth_ablation.py): the same scene with one component replaced.
    Without ablations the frame is the benchmark's; with them the truth, hints and the other draws stay, and only
    the named component changes (the glow, the JPEG, the PSF, the cloud map)."""
    from dataclasses import replace as _replace

    from jaxlimb.render.independent import ABLATIONS, EARTH_FAMILIES
    from jaxlimb.render.independent.families import _ablated_psf

    def draw(ablate=()):
        rng = np.random.default_rng([2026, 1, EARTH_FAMILIES.index("combined"), 1])  # families.py combined 1: far
        return earth_case("combined", rng, far=True, ablate=ablate)

    base = draw()
    assert base.meta["glow"] is not None and base.meta["jpeg"] is not None and base.meta["psf"] == "airy"
    assert "ablated" not in base.meta
    again = draw(())
    assert np.array_equal(again.image, base.image)
    for ablate, key, value in ((("no_glow",), "glow", None), (("no_jpeg",), "jpeg", None), (("psf_core",), "psf", "gaussian")):
        c = draw(ablate)
        assert c.truth == base.truth and c.hints == base.hints
        assert c.meta[key] == value and c.meta["ablated"] == list(ablate)
        assert {k: v for k, v in c.meta.items() if k not in (key, "ablated")} == {k: v for k, v in base.meta.items() if k != key}
        assert not np.array_equal(c.image, base.image)
    clouds = draw(("reseed_clouds",))
    assert clouds.meta["glow"] == base.meta["glow"] and not np.array_equal(clouds.image, base.image)
    # the round PSF has the smear's per-axis variance, the core its Gaussian
    smear = Psf(kind=PsfKind.MOTION, sigma=0.6, length=3.0, angle_deg=30.0)
    assert _ablated_psf(smear, ("psf_round",)).sigma == pytest.approx(math.sqrt(0.36 + 9.0 / 24.0))
    assert _ablated_psf(smear, ("psf_core",)) == _replace(Psf(kind=PsfKind.GAUSSIAN, sigma=0.6))
    plain = draw(("no_clouds",))  # a uniform albedo under the same geometry, glow, PSF and noise draws
    assert plain.truth == base.truth and plain.meta["glow"] == base.meta["glow"]
    assert not np.array_equal(plain.image, base.image) and not np.array_equal(plain.image, clouds.image)
    assert set(ABLATIONS) == {"psf_core", "psf_round", "no_glow", "no_jpeg", "reseed_clouds", "no_clouds"}
    with pytest.raises(ValueError, match="unknown ablations"):
        draw(("no_such_thing",))


def test_spots_map_varies_everywhere_within_its_bounds():
    """The ``spots`` albedo: no flat plateau (it changes across a limb window of a few degrees almost everywhere),
    dips of at most the drawn depths, the gradient bounded."""
    from jaxlimb.render.independent import SpotsMap

    m = SpotsMap.draw(np.random.default_rng(3))
    u = np.random.default_rng(4).normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    a = m(u)
    assert a.min() > 0.0 and a.max() <= 1.04 + 1e-12
    v = u + 0.09 * np.cross(u, [0.0, 0.0, 1.0])  # ~5 deg away (away from the poles)
    change = np.abs(m(v) - a)
    assert np.mean(change > 0.005) > 0.5  # the albedo changes across a limb window on most of the body
    assert m(u.reshape(40, 100, 3)).shape == (40, 100)


def test_albedo_case_refuses_an_unknown_map():
    from jaxlimb.render.independent.families import ALBEDO_KINDS, albedo_case

    assert "spots" in ALBEDO_KINDS and "uniform" in ALBEDO_KINDS
    with pytest.raises(ValueError, match="unknown albedo"):
        albedo_case("moon", 150_000.0, 45.0, "stripes", 1, 0)
