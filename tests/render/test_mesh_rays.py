"""The independent ray-traced mesh renderer (jaxlimb.render.independent.mesh_rays): truth, area,
shadows, smooth shading, generated cratered bodies."""

import dataclasses
import math

import numpy as np
import pytest
import trimesh

from jaxlimb.geometry.camera import Camera
from jaxlimb.render.independent import Pinhole, Photometry, Psf, Reflectance
from jaxlimb.render.independent.mesh_rays import MeshScene, cratered_body, render_mesh_frame, render_radiance
from jaxlimb.render.independent.sensor import SensorSpec

pytest.importorskip("embreex")  # the Embree ray caster (a test dependency); trimesh's own is slow but exact

CAM = Camera(focal_length_mm=16.0, pixel_pitch_mm=0.0022, rows=200, cols=220)
PIN = Pinhole.from_camera(CAM)


def _sphere_scene(sun, offset_px=(12.3, -20.6), law=Reflectance.LAMBERT, **kw):
    ico = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    D = 100.0
    t = np.array([offset_px[1] * D / PIN.focal_px, offset_px[0] * D / PIN.focal_px, D])
    return MeshScene(np.asarray(ico.vertices), np.asarray(ico.faces), np.eye(3), t, np.asarray(sun, float),
                     Photometry(law=law), psf=Psf(sigma=0.7), **kw)


def test_sphere_area_and_center_at_zero_phase():
    sc = _sphere_scene([0.0, 0.0, -1.0])
    sc = dataclasses.replace(sc, sun_dir_camera=-sc.t_camera_km / np.linalg.norm(sc.t_camera_km))  # zero phase
    rad, _ = render_radiance(sc, PIN, supersample=4)
    r_px = PIN.focal_px / math.sqrt(100.0**2 - 1.0)
    truth = np.array(PIN.project(sc.t_camera_km))
    # zero phase, Lambert: radiance mu; the disc integral is (2/3) pi r^2 (mu over the projected disc)
    assert rad.sum() == pytest.approx(2.0 / 3.0 * math.pi * r_px**2, rel=0.01)
    rr, cc = np.mgrid[0 : CAM.rows, 0 : CAM.cols]
    centroid = np.array([(rad * rr).sum(), (rad * cc).sum()]) / rad.sum()
    assert np.linalg.norm(centroid - truth) < 0.02


def test_truth_is_projection_of_mesh_origin():
    sc = _sphere_scene([0.3, 0.0, -1.0])
    img, truth = render_mesh_frame(sc, PIN, np.random.default_rng(0))
    assert img.dtype == np.uint16 and img.shape == CAM.shape
    np.testing.assert_allclose(truth, PIN.project(sc.t_camera_km))
    np.testing.assert_allclose(truth, [CAM.principal_point_rc[0] + 12.3, CAM.principal_point_rc[1] - 20.6], atol=1e-9)


def test_cast_shadows_fall_where_a_body_hides_the_sun():
    big = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    moonlet = trimesh.creation.icosphere(subdivisions=3, radius=0.35)
    moonlet.apply_translation([1.6, 0.0, -0.6])  # sunward of the big sphere: its shadow falls on it
    both = trimesh.util.concatenate([big, moonlet])
    s = np.array([1.0, 0.0, -0.35]) / math.hypot(1.0, 0.35)
    sc = MeshScene(np.asarray(both.vertices), np.asarray(both.faces), np.eye(3), np.array([0.0, 0.0, 120.0]), s,
                   Photometry(law=Reflectance.LAMBERT), psf=Psf(sigma=0.5))
    lit, _ = render_radiance(sc, PIN, seed=1)
    unshadowed, _ = render_radiance(dataclasses.replace(sc, shadows=False), PIN, seed=1)
    assert np.all(lit <= unshadowed + 1e-9)
    darker = (unshadowed - lit) > 0.2 * unshadowed.max()
    assert darker.sum() > 50
    rr, cc = np.nonzero(darker)  # on the big sphere, between its centre and the moonlet (+col side)
    assert np.all(cc > CAM.principal_point_rc[1])


def test_smooth_normals_remove_facet_edges():
    ico = trimesh.creation.icosphere(subdivisions=2, radius=1.0)  # coarse: flat facets show
    sc = MeshScene(np.asarray(ico.vertices), np.asarray(ico.faces), np.eye(3), np.array([0.0, 0.0, 90.0]),
                   np.array([0.5, 0.0, -1.0]) / math.sqrt(1.25), Photometry(law=Reflectance.LAMBERT), psf=Psf(sigma=0.3))
    smooth, _ = render_radiance(sc, PIN, seed=2)
    flat, _ = render_radiance(dataclasses.replace(sc, smooth_normals=False), PIN, seed=2)
    inner = smooth > 0.3 * smooth.max()
    lap = lambda a: np.abs(a[1:-1, 1:-1] * 4 - a[:-2, 1:-1] - a[2:, 1:-1] - a[1:-1, :-2] - a[1:-1, 2:])[inner[1:-1, 1:-1]].mean()
    assert lap(smooth) < 0.7 * lap(flat)  # measured 0.55


def test_cratered_body_is_closed_reproducible_and_new():
    V, F = cratered_body(5, subdivisions=3)
    tm = trimesh.Trimesh(V, F, process=False)
    assert tm.is_watertight and tm.volume > 0
    V2, _ = cratered_body(5, subdivisions=3)
    np.testing.assert_array_equal(V, V2)
    V3, _ = cratered_body(6, subdivisions=3)
    assert np.abs(V - V3).max() > 0.5


def test_sensor_and_variegation():
    sc = _sphere_scene([0.0, 0.0, -1.0], law=Reflectance.HAPKE, albedo_depth=0.3, albedo_seed=4,
                       sensor=SensorSpec(bits=8, read_noise_dn=1.0, background_dn=5.0))
    img, _ = render_mesh_frame(sc, PIN, np.random.default_rng(3))
    assert img.dtype == np.uint8 and img.max() > 150
    plain, _ = render_radiance(dataclasses.replace(sc, albedo_depth=0.0), PIN, seed=0)
    vari, _ = render_radiance(sc, PIN, seed=0)
    on = plain > 0.2 * plain.max()
    ratio = vari[on] / plain[on]
    assert ratio.std() > 0.03  # a variegated surface, not a uniform one


def test_jitter_does_not_displace_the_frame():
    """Every pixel has its own sub-pixel jitter: one pattern shared by all pixels moved the whole frame by its mean
    (~0.03 px per axis at 3 x 3 rays), so renders of one scene with other seeds disagreed by up to 0.1 px."""
    sc = _sphere_scene([0.0, 0.0, -1.0])
    sc = dataclasses.replace(sc, sun_dir_camera=-sc.t_camera_km / np.linalg.norm(sc.t_camera_km))
    rr, cc = np.mgrid[0 : CAM.rows, 0 : CAM.cols]
    cents = []
    for seed in range(6):
        rad, _ = render_radiance(sc, PIN, supersample=3, seed=seed)
        cents.append([(rad * rr).sum() / rad.sum(), (rad * cc).sum() / rad.sum()])
    spread = np.ptp(np.array(cents), axis=0)
    assert spread.max() < 0.01  # measured 0.001; one pattern shared by all pixels: 0.100
