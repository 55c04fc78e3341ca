"""Silhouettes, contours and features (Eq. 10-14 of Wu et al.)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
import trimesh

from jaxlimb.irregular.features import (
    far_point_candidates,
    features_from_contours,
    features_from_mask,
    log_hu,
    raw_moments_polygon,
)
from jaxlimb.irregular.mesh import validate_mesh
from jaxlimb.irregular.silhouette import (
    figure_extents,
    fill_triangles_exact,
    mesh_topology,
    render_silhouette,
    segment_body,
)
from jaxlimb.irregular.views import ViewSphereOptions, template_rotations
from jaxlimb.errors import NoBodyError, TooBigError, TooSmallError


def _poly_mask(poly, shape=(200, 220)):
    m = np.zeros(shape, np.uint8)
    cv2.fillPoly(m, [np.asarray(poly, np.int32)], 1)
    return m


def test_hu_matches_opencv():
    m = _poly_mask([[20, 30], [150, 40], [170, 160], [60, 120], [30, 180]])
    f = features_from_mask(m)
    ref = cv2.HuMoments(cv2.moments(m, binaryImage=True)).ravel()
    assert np.allclose(f.hu, ref, rtol=1e-9, atol=1e-15)


def test_polygon_moments_match_opencv_contour_moments():
    poly = np.array([[20.5, 30.0], [150.0, 40.25], [170.0, 160.0], [60.0, 120.0], [30.0, 180.0]])
    mine = raw_moments_polygon(poly)
    mm = cv2.moments(poly.astype(np.float32))
    ref = [mm[k] for k in ("m00", "m10", "m01", "m20", "m11", "m02", "m30", "m21", "m12", "m03")]
    assert np.allclose(mine, ref, rtol=1e-6)
    assert np.allclose(raw_moments_polygon(poly[::-1]), mine)  # orientation-independent


def test_eq14_area_and_center_of_rectangle():
    m = np.zeros((50, 60), np.uint8)
    m[10:20, 5:35] = 1
    f = features_from_mask(m)
    assert f.area == 300
    assert np.allclose(f.center_rc, [14.5, 19.5])
    assert f.orientation == pytest.approx(0.0, abs=1e-12)  # long axis along x = col


def test_hu_invariance_and_mirror_sign():
    poly = np.array([[40, 30], [150, 40], [170, 160], [90, 120], [30, 150]], float)
    base = features_from_contours([poly.reshape(-1, 1, 2)])
    ang = 0.7
    rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    moved = (poly - poly.mean(0)) @ rot.T * 1.7 + 300
    f2 = features_from_contours([moved.reshape(-1, 1, 2)])
    assert np.allclose(f2.hu, base.hu, rtol=1e-8)
    mirrored = poly * np.array([-1.0, 1.0])
    f3 = features_from_contours([mirrored.reshape(-1, 1, 2)])
    assert np.allclose(f3.hu[:6], base.hu[:6], rtol=1e-8)
    assert f3.hu[6] == pytest.approx(-base.hu[6], rel=1e-8)
    assert abs(base.hu[6]) > 1e-6 * abs(base.hu[0]) ** 3.5  # the test shape is chiral


def test_log_hu_guard_is_continuous_and_keeps_sign():
    h = np.array([[0.2, 1e-3, 1e-4, 1e-5, 1e-14, -1e-16, 1e-20], [0.2, 1e-3, 1e-4, 1e-5, -1e-14, 1e-16, -1e-20]])
    g = log_hu(h)
    # near-zero moments of opposite sign map to nearly the same value (no blow-up like log|h|)
    assert np.all(np.abs(g[0, 4:] - g[1, 4:]) < 0.01)
    assert np.all(np.sign(g[:, 4:]) == np.sign(h[:, 4:]))
    assert np.all(np.isfinite(log_hu(np.zeros(7))))


def test_far_point_candidates_separated():
    c = np.array([[10.0, 0.0], [9.9, 0.5], [0.0, 9.95], [-9.0, 0.0], [0.0, -3.0]])
    v = far_point_candidates(c, np.zeros(2), n=3)
    assert np.allclose(v[0], [10.0, 0.0])
    assert np.allclose(v[1], [0.0, 9.95])  # (9.9, 0.5) is too close in angle to the first
    assert np.allclose(v[2], [-9.0, 0.0])


def test_silhouette_equals_union_of_triangles(thebe):
    """The contour-generator outline fill equals the per-triangle union (the slow reference)."""
    topo = mesh_topology(thebe)
    _, _, R = template_rotations(ViewSphereOptions(30.0, pole_axis="y"))
    S, D = 200, 20 * thebe.max_radius
    f = 0.4 * S * D / thebe.max_radius
    pp = ((S - 1) / 2, (S - 1) / 2)
    for i in (0, 7, 20, 33):
        t = np.array([0.0, 0.0, D])
        mask, contours = render_silhouette(topo, R[i], t, f, pp, (S, S))
        Xc = thebe.vertices @ R[i].T + t
        rc = np.stack([pp[0] + f * Xc[:, 1] / Xc[:, 2], pp[1] + f * Xc[:, 0] / Xc[:, 2]], -1)
        ref = fill_triangles_exact(rc[thebe.faces], (S, S))
        assert len(contours) == 1
        # agree up to boundary pixels (different edge rasterisation rules)
        diff = int((mask != ref).sum())
        perimeter = cv2.arcLength(contours[0], True)
        assert diff < 0.25 * perimeter
        fm, fr = features_from_mask(mask), features_from_mask(ref)
        assert np.allclose(fm.center_rc, fr.center_rc, atol=0.1)


def test_template_features_subpixel_accurate_on_sphere():
    """Polygon moments of the traced contour recover a sphere's disc to 0.5 % / 0.1 px."""
    ico = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    m = validate_mesh(np.asarray(ico.vertices), np.asarray(ico.faces))
    topo = mesh_topology(m)
    S, f, D = 256, 2000.0, 20.0
    r_true = f * math.tan(math.asin(1 / D))
    for off in ((0.0, 0.0), (0.3, 0.7), (0.25, 0.5)):
        pp = ((S - 1) / 2 + off[0], (S - 1) / 2 + off[1])
        _, contours = render_silhouette(topo, np.eye(3), np.array([0, 0, D]), f, pp, (S, S))
        ft = features_from_contours(contours)
        assert ft.area == pytest.approx(math.pi * r_true**2, rel=5e-3)
        assert np.allclose(ft.center_rc, pp, atol=0.1)


def test_lit_silhouette_is_part_of_full(thebe):
    topo = mesh_topology(thebe)
    R = np.eye(3)
    t = np.array([0.0, 0.0, 20 * thebe.max_radius])
    full, _ = render_silhouette(topo, R, t, 3000.0, (149.5, 149.5), (300, 300))
    sun = np.array([math.sin(math.radians(60)), 0.0, -math.cos(math.radians(60))])
    lit, _ = render_silhouette(topo, R, t, 3000.0, (149.5, 149.5), (300, 300), sun_dir_camera=sun)
    assert 0.4 * full.sum() < lit.sum() < 0.95 * full.sum()
    assert (lit & ~full.astype(bool)).sum() < 0.01 * lit.sum()
    cols = np.nonzero(lit.any(axis=0))[0]
    assert cols.mean() > np.nonzero(full.any(axis=0))[0].mean()  # lit toward +x (+col), where the Sun is


def test_segment_body_and_checks():
    img = np.full((100, 120), 5.0)
    img[30:60, 40:90] = 100.0
    img[5, 5] = 100.0  # a hot pixel is not the body
    mask, thr = segment_body(img)
    assert 5 < thr < 100 and mask.sum() == 30 * 50
    with pytest.raises(NoBodyError):
        segment_body(np.zeros((50, 50)))
    tiny = np.zeros((50, 50))
    tiny[10:13, 10:13] = 1
    with pytest.raises(TooSmallError):
        segment_body(tiny)
    edge = np.zeros((50, 50))
    edge[0:20, 10:30] = 1
    with pytest.raises(TooBigError):
        segment_body(edge)


def test_figure_extents_are_the_pixel_maxima_of_every_component():
    """Extents from the outer contours = max over all figure pixels, for blobs, holes and several pieces."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        mask = np.zeros((120, 140), np.uint8)
        for _ in range(int(rng.integers(1, 4))):
            c = rng.uniform([10, 10], [110, 130])
            cv2.ellipse(mask, (int(c[1]), int(c[0])), (int(rng.integers(2, 30)), int(rng.integers(2, 20))), float(rng.uniform(0, 180)), 0, 360, 1, -1)
        mask[rng.random(mask.shape) < 0.02] = 0  # holes and ragged edges
        ang = rng.uniform(0, 2 * np.pi, 5)
        axes = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        rr, cc = np.nonzero(mask)
        brute = (np.stack([rr, cc], axis=1).astype(float) @ axes.T).max(axis=0)
        np.testing.assert_allclose(figure_extents(mask, axes), brute, atol=1e-9)
    with pytest.raises(NoBodyError):
        figure_extents(np.zeros((10, 10), np.uint8), axes)
