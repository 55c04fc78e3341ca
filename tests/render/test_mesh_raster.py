"""The mesh renderer's face-index buffer (jaxlimb.render.mesh.rasterise) and its row-wise cross product: the
painter's fill is OpenCV's, facet by facet far to near, and ``cross_rows`` gives the floats of ``np.cross``."""

import cv2
import numpy as np
import pytest

from jaxlimb.geometry.camera import Camera
from jaxlimb.irregular.shapes import gaussian_sphere
from jaxlimb.render.mesh import (
    cross_rows,
    look_at_rotation,
    rasterise,
    shadow_fractions,
)


@pytest.mark.parametrize("shape_b", [(500, 3), (3,)])
def test_cross_rows_is_np_cross_bit_for_bit(shape_b):
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(500, 3)) * 1e3, rng.normal(size=shape_b)
    assert np.array_equal(cross_rows(a, b), np.cross(a, b))
    assert np.array_equal(cross_rows(b, a), np.cross(b, a))
    assert cross_rows(a.astype(np.float32), a[::-1].astype(np.float32)).dtype == np.float32


def _painter_reference(Xc, F, cam, ss):  # type: ignore[no-untyped-def]
    """``cv2.fillConvexPoly`` of each front facet in turn, far to near (centroid depth): the definition."""
    ras = rasterise(Xc, F, cam, ss, exact=False)
    rows_cols = np.stack([cam.principal_point_rc[0] + cam.focal_px * Xc[:, 1] / Xc[:, 2],
                          cam.principal_point_rc[1] + cam.focal_px * Xc[:, 0] / Xc[:, 2]], axis=1)  # fmt: skip
    sub = (rows_cols - [ras.r0, ras.c0] + 0.5) * ss - 0.5
    cen = Xc[F].mean(axis=1)
    front = np.nonzero(ras.mu > 0)[0]
    buf = np.zeros_like(ras.buf)
    for k in front[np.argsort(-cen[front, 2])]:
        cv2.fillConvexPoly(buf, np.round(sub[F[k]][:, ::-1] * 256.0).astype(np.int32), int(k) + 1, cv2.LINE_8, 8)
    return ras.buf, buf


@pytest.mark.parametrize("seed", [1, 2])
def test_rasterise_is_the_painters_fill_facet_by_facet(seed):
    mesh = gaussian_sphere(seed=seed, radius_km=10.0, subdivisions=3)
    cam = Camera(rows=160, cols=180)
    R = look_at_rotation(np.random.default_rng(seed).normal(size=3), roll_rad=0.3 * seed)
    Xc = np.asarray(mesh.vertices) @ R.T + [0.4, -0.3, mesh.max_radius * cam.focal_px / 60.0]
    for ss in (1, 4):
        got, ref = _painter_reference(Xc, np.asarray(mesh.faces, dtype=np.int64), cam, ss)
        assert np.array_equal(got, ref)


def test_shadow_fractions_keep_the_mesh_normals_between_sun_directions():
    mesh = gaussian_sphere(seed=3, radius_km=10.0, subdivisions=3)
    V, F = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    first = shadow_fractions(V, F, np.array([0.3, 0.5, 0.8]))
    other = shadow_fractions(V, F, np.array([-0.6, 0.2, 0.7]))  # the same mesh: its cached normals
    again = shadow_fractions(V.copy(), F.copy(), np.array([-0.6, 0.2, 0.7]))  # another mesh object: computed anew
    assert np.array_equal(other, again) and not np.array_equal(first, other)
    assert np.all((0.0 <= other) & (other <= 1.0))
