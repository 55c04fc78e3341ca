"""Model images of render-and-register: attitude columns from one render, pyramid levels."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from jaxlimb.geometry.camera import Camera
from jaxlimb.irregular.model_render import attitude_columns, downsample, level_camera, render_window
from jaxlimb.irregular.register.gauss_newton import rotvec_matrix
from jaxlimb.render.mesh import render_mesh

CAM = Camera(focal_length_mm=30.0, pixel_pitch_mm=0.02, rows=400, cols=400)


def _pose(mesh, size_px=150.0):
    from scipy.spatial.transform import Rotation

    D = 2.0 * mesh.max_radius * CAM.focal_px / size_px
    t = np.array([0.03 * D, -0.02 * D, D])
    sun = np.array([0.6, 0.2, -1.0])
    return Rotation.from_rotvec([0.4, -0.7, 0.2]).as_matrix(), t, sun / np.linalg.norm(sun)


def _window(t, mesh):
    P = np.array(CAM.principal_point_rc) + CAM.focal_px * t[[1, 0]] / t[2]
    rad = CAM.focal_px * mesh.max_radius / (t[2] - mesh.max_radius)
    return np.floor(P - rad - 8).astype(int), np.ceil(P + rad + 8).astype(int)


def test_render_window_matches_render_mesh(lumpy):
    R, t, sun = _pose(lumpy)
    lo, hi = _window(t, lumpy)
    m = render_window(lumpy, CAM, R, t, sun, lo, hi, 4)
    full = render_mesh(lumpy.vertices, lumpy.faces, CAM, R, t, sun).coverage
    assert np.abs(m.C - full[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1]).max() < 1e-6
    assert m.C.sum() > 1000 and m.flow is None


@pytest.mark.parametrize("sigma", [2.0, 6.0])
def test_attitude_columns_agree_with_central_differences(lumpy, sigma):
    """One render's analytic columns vs two renders per axis at +-1 deg (corr > 0.85, scale within 25 %)."""
    R, t, sun = _pose(lumpy)
    lo, hi = _window(t, lumpy)
    m = render_window(lumpy, CAM, R, t, sun, lo, hi, 4, jacobian=True)
    blur = lambda a: cv2.GaussianBlur(a, (0, 0), sigma)  # noqa: E731
    cols = attitude_columns(m, 0.05, blur)
    eps = math.radians(1.0)
    for i in range(3):
        w = np.zeros(3)
        w[i] = eps
        p, q = (render_window(lumpy, CAM, rotvec_matrix(s * w) @ R, t, sun, lo, hi, 4) for s in (1, -1))
        cd = (blur(p.M - 0.05 * p.C) - blur(q.M - 0.05 * q.C)).ravel() / (2 * eps)
        corr = np.corrcoef(cd, cols[:, i])[0, 1]
        scale = float(cd @ cols[:, i]) / float(cols[:, i] @ cols[:, i])
        assert corr > 0.85 and 0.75 < scale < 1.25, (i, corr, scale)


def test_pyramid_level_is_the_box_average_of_the_fine_render(lumpy):
    """The level-k camera renders what box-averaging the fine render gives (coordinates x = k X + (k-1)/2)."""
    R, t, sun = _pose(lumpy)
    k = 4
    fine = render_mesh(lumpy.vertices, lumpy.faces, CAM, R, t, sun).image
    cam_k = level_camera(CAM, k)
    coarse = render_mesh(lumpy.vertices, lumpy.faces, cam_k, R, t, sun).image
    assert coarse.shape == (100, 100)
    diff = np.abs(coarse - downsample(fine, k))
    assert diff.mean() < 0.3 and np.percentile(diff, 99) < 6.0
    # the body centre maps by x = k X + (k - 1) / 2
    c_fine = np.array(CAM.principal_point_rc) + CAM.focal_px * t[[1, 0]] / t[2]
    c_k = np.array(cam_k.principal_point_rc) + cam_k.focal_px * t[[1, 0]] / t[2]
    np.testing.assert_allclose(k * c_k + (k - 1) / 2.0, c_fine, atol=1e-9)


def test_coarse_cast_shadows_switch_only_the_coarse_levels(lumpy):
    """``RegisterOptions.coarse_cast_shadows=False``: no cast shadows from pyramid factor ``COARSE_MIN_LEVEL`` on."""
    from jaxlimb.irregular.register import RegisterOptions
    from jaxlimb.irregular.register.pyramid import COARSE_MIN_LEVEL, Pyramid, render_level

    R, t, _ = _pose(lumpy, size_px=360.0)
    sun = np.array([0.95, 0.0, 0.3]) / np.linalg.norm([0.95, 0.0, 0.3])  # ~107 deg phase: long cast shadows
    pyr = Pyramid(np.zeros(CAM.shape), CAM, np.ones(CAM.shape, bool))
    P = np.array(CAM.principal_point_rc) + CAM.focal_px * t[[1, 0]] / t[2]
    base = RegisterOptions()
    for k in (1, COARSE_MIN_LEVEL):
        M = {name: render_level(pyr, lumpy, sun, o, k, (R, P, float(np.linalg.norm(t))), False, None).model.M
             for name, o in (("on", base), ("off", RegisterOptions(cast_shadows=False)),
                             ("coarse_off", RegisterOptions(coarse_cast_shadows=False)))}  # fmt: skip
        assert not np.array_equal(M["on"], M["off"])  # the pose has cast shadows
        np.testing.assert_array_equal(M["coarse_off"], M["on"] if k < COARSE_MIN_LEVEL else M["off"])


def test_clustered_mesh_is_coarser_and_keeps_the_outline(lumpy):
    """Vertex clustering on a coarse level: far fewer facets, coverage within a cell of the full mesh's."""
    from jaxlimb.irregular.model_render import clustered_mesh

    R, t, sun = _pose(lumpy, size_px=60.0)
    cell = 3.0 * t[2] / CAM.focal_px  # three pixels at this range
    coarse = clustered_mesh(lumpy, cell)
    assert len(coarse.faces) < 0.6 * len(lumpy.faces)
    q = 2.0 ** (math.floor(2.0 * math.log2(cell)) / 2.0)
    assert clustered_mesh(lumpy, q * 1.01) is clustered_mesh(lumpy, q * 1.4)  # cells rounded: reused between iterations
    lo, hi = _window(t, lumpy)
    full, simp = (render_window(m, CAM, R, t, sun, lo, hi, 4) for m in (lumpy, coarse))
    assert abs(simp.C.sum() - full.C.sum()) < 0.05 * full.C.sum()
    blur = lambda a: cv2.GaussianBlur(a, (0, 0), 2.0)  # noqa: E731
    assert np.abs(blur(simp.C) - blur(full.C)).max() < 0.25


def test_mesh_renderer_does_not_import_the_ellipsoid_renderer():
    import subprocess
    import sys

    code = "import sys, jaxlimb.irregular.locate; print('jaxlimb.render.body' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False"


@pytest.mark.parametrize("n_split", [1, 3])
def test_vertex_normal_does_not_depend_on_the_triangulation(n_split):
    """Two planar wedges of 90 deg meet at a vertex; however the first is cut into triangles and however
    large they are, the vertex normal is the bisector of the two planes' normals (angle weights)."""
    from jaxlimb.irregular.model_render import _vertex_normals

    th = np.linspace(0.0, 0.5 * math.pi, n_split + 1)
    arc = 3.0 * np.stack([np.cos(th), np.sin(th), np.zeros_like(th)], axis=1)  # plane z = 0, large triangles
    d2 = np.array([0.0, -1.0, 1.0]) / math.sqrt(2.0)  # plane through x and d2, one small triangle
    V = np.vstack([np.zeros(3), arc, d2, [1.0, 0.0, 0.0]])
    k = len(arc)
    F = np.array([[0, 1 + i, 2 + i] for i in range(n_split)] + [[0, k + 1, k + 2]])
    want = np.array([0.0, 0.0, 1.0]) + np.array([0.0, 1.0, 1.0]) / math.sqrt(2.0)
    np.testing.assert_allclose(_vertex_normals(V, F)[0], want / np.linalg.norm(want), atol=1e-9)


def test_body_vertex_normals_rotate_with_the_body(lumpy):
    """The cached body-frame vertex normals, rotated, are the normals of the rotated (and moved) vertices."""
    from jaxlimb.irregular.model_render import _vertex_normals, body_vertex_normals

    R, t, _ = _pose(lumpy)
    want = _vertex_normals(lumpy.vertices @ R.T + t, lumpy.faces)
    np.testing.assert_allclose(body_vertex_normals(lumpy) @ R.T, want, atol=1e-12)
    assert body_vertex_normals(lumpy) is body_vertex_normals(lumpy)


def test_shadow_map_depends_on_the_sun_direction_alone(lumpy):
    """The lit fractions of a Sun direction are the same whatever directions were asked before (the map is computed
    at its ~0.25 deg cell's own direction; before, the first direction seen in a cell made it, so a registration
    depended on the calls before it), and a direction in the same cell reuses the map."""
    from scipy.spatial.transform import Rotation

    import jaxlimb.render.mesh as rm

    sun = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    near = [Rotation.from_rotvec(np.radians(d) * np.array([1.0, 0.0, 0.0])).apply(sun) for d in (0.1, -0.1, 0.05)]
    rm._SHADOWS.clear()
    fresh = rm.shadow_fractions(lumpy.vertices, lumpy.faces, sun).copy()
    for first in near:
        rm._SHADOWS.clear()
        rm.shadow_fractions(lumpy.vertices, lumpy.faces, first)
        np.testing.assert_array_equal(rm.shadow_fractions(lumpy.vertices, lumpy.faces, sun), fresh)
    rm._SHADOWS.clear()
    a = rm.shadow_fractions(lumpy.vertices, lumpy.faces, sun)
    assert rm.shadow_fractions(lumpy.vertices, lumpy.faces, sun * 1.0000001) is a


@pytest.mark.parametrize("ss", [4, 8])
def test_raster_outline_is_not_dilated(ss):
    """A convex mesh's coverage is the area of its outline (the hull of the projected vertices), not the
    outline dilated by half a sub-pixel (``cv2.fillConvexPoly`` fills pixels its edges only touch:
    +0.5/ss px along the whole outline before the trim)."""
    import trimesh
    from scipy.spatial import ConvexHull

    from jaxlimb.render.mesh import rasterise

    V = trimesh.creation.icosphere(subdivisions=3).vertices * 1.0
    t = np.array([0.7, -0.4, 30.0])  # ~60 px radius at f = 1500 px
    Xc = V + t
    F = np.asarray(trimesh.creation.icosphere(subdivisions=3).faces)
    ras = rasterise(Xc, F, CAM, ss)
    area = float((ras.buf > 0).sum()) / ss**2
    rc = np.stack([CAM.principal_point_rc[0] + CAM.focal_px * Xc[:, 1] / Xc[:, 2],
                   CAM.principal_point_rc[1] + CAM.focal_px * Xc[:, 0] / Xc[:, 2]], axis=1)  # fmt: skip
    hull = ConvexHull(rc)
    mean_offset_px = (area - hull.volume) / hull.area  # (2-D hull: volume = area, area = perimeter)
    assert abs(mean_offset_px) < 0.02, mean_offset_px  # 0.13 and 0.063 px untrimmed


@pytest.mark.parametrize("ss", [4, 8])
def test_raster_facets_cover_exactly_their_subpixel_centres(ss):
    """Between facets too, every sub-pixel shows the facet containing its centre: on a convex mesh (no facet
    hides another) each front facet's sub-pixel count equals the number of sub-pixel centres inside its
    projected triangle.  The painter's fill alone lets every nearer facet overlap its farther neighbour by
    half a sub-pixel (``cv2.fillConvexPoly``): 8 % of the sub-pixels showed a facet not containing them,
    and at 90 deg phase that moves the lit side's shading pattern toward the Sun."""
    import trimesh

    from jaxlimb.render.mesh import _contains, _edge_coefficients, rasterise

    ico = trimesh.creation.icosphere(subdivisions=3)
    Xc = np.asarray(ico.vertices) + np.array([0.7, -0.4, 30.0])  # ~60 px radius at f = 1500 px
    F = np.asarray(ico.faces)
    ras = rasterise(Xc, F, CAM, ss)
    rr, cc = np.nonzero(ras.buf > 0)
    f = CAM.focal_px
    rc = np.stack([CAM.principal_point_rc[0] + f * Xc[:, 1] / Xc[:, 2], CAM.principal_point_rc[1] + f * Xc[:, 0] / Xc[:, 2]], axis=1)
    sub = (rc - np.array([ras.r0, ras.c0]) + 0.5) * ss - 0.5
    own = _contains(_edge_coefficients(sub, F).reshape(-1, 9), ras.buf[rr, cc], rr.astype(np.float32), cc.astype(np.float32))
    assert own.mean() > 0.9999, 1.0 - own.mean()  # 0.082 (ss=4) and 0.042 (ss=8) of them outside their facet before
    counts = np.bincount(ras.buf.ravel(), minlength=len(F) + 1)[1:]
    assert counts.sum() > 10000 and (counts[ras.mu <= 0] == 0).all()
