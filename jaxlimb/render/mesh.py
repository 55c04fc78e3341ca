"""Shaded images of a triangle mesh with exact truth (for the irregular-body LOS tests).

Rendering: the window around the projected body is rasterised at
``supersample`` x the pixel resolution with a painter's algorithm (front-facing
faces sorted far-to-near by centroid depth, each filled with
``cv2.fillConvexPoly`` into a face-index buffer), every sub-pixel takes the
flat-shaded radiance of its face, and sub-pixels are averaged per pixel (box
filter = exact area coverage up to the sub-pixel grid: anti-aliased edges).

Reflectance (``mu0 = n.s`` toward the Sun, ``mu = n.e`` toward the camera):

* ``"lommel-seeliger"``: ``2 albedo mu0 / (mu0 + mu)`` (1x ``albedo`` at zero
  phase, the usual model for dark airless bodies: no limb darkening);
* ``"lambert"``: ``albedo mu0``.

Faces with ``mu0 <= 0`` are dark; a face turned toward the Sun is darkened by the share of it
the body itself hides from the Sun (cast shadows, :func:`shadow_fractions`, per face).

OpenCV's polygon fill includes the pixels its edges pass through, i.e. every
facet is dilated by about half a *sub-pixel* (``0.5 / supersample`` px, 0.125 px
at the default 4x), and the painter's order lets every nearer facet overlap its
farther neighbour by that much.  :func:`_exact_edges` undoes it: every sub-pixel
shows the nearest facet that contains its centre (sky where none does), so each
facet covers exactly the sub-pixel centres inside it, on the outline and between
facets alike.

Truth: the image of the body centre (mesh origin) is ``camera.project(t)``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from itertools import repeat

import cv2
import numpy as np

from .._identity_cache import IdentityCache
from ..errors import ConfigError, GeometryError
from ._masks import boundary_mask


@dataclass(frozen=True)
class MeshRenderOptions:
    """Options of :func:`render_mesh`.

    Parameters
    ----------
    supersample
        Sub-pixels per pixel side (1..16).
    reflectance
        ``"lommel-seeliger"`` or ``"lambert"``.
    albedo
        Radiance scale (DN) of a face seen at zero phase.
    background
        Background level (DN).
    noise_sigma
        Standard deviation of additive Gaussian noise (DN); 0 = none.
    seed
        Seed of the noise generator.
    quantize_bits
        Round to integers and clip to ``[0, 2**bits - 1]`` (``None``: keep floats).
    cast_shadows
        Darken each face by the share of its area the body itself hides from the Sun
        (:func:`shadow_fractions`).
    """

    supersample: int = 4
    reflectance: str = "lommel-seeliger"
    albedo: float = 200.0
    background: float = 10.0
    noise_sigma: float = 0.0
    seed: int = 0
    quantize_bits: int | None = None
    cast_shadows: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.supersample, int) and 1 <= self.supersample <= 16):
            raise ConfigError(f"`supersample` must be an integer in [1, 16], got {self.supersample!r}")
        if self.reflectance not in ("lommel-seeliger", "lambert"):
            raise ConfigError(f"`reflectance` must be 'lommel-seeliger' or 'lambert', got {self.reflectance!r}")
        if not self.noise_sigma >= 0:
            raise ConfigError(f"`noise_sigma` must be >= 0, got {self.noise_sigma!r}")
        if self.quantize_bits is not None and self.quantize_bits not in (8, 10, 12, 14, 16):
            raise ConfigError(f"`quantize_bits` must be None or one of 8..16 (even), got {self.quantize_bits!r}")


@dataclass(frozen=True)
class MeshRender:
    """A rendered image and its truth.

    Attributes
    ----------
    image
        float64 ``(rows, cols)``.
    center_rc
        Exact image of the body centre (mesh origin), ``(row, col)``.
    coverage
        Fraction of each pixel covered by the body (lit or not), ``(rows, cols)``.
    """

    image: np.ndarray
    center_rc: np.ndarray
    coverage: np.ndarray


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product ``a x b`` of ``(..., 3)`` arrays (broadcast): the floats of ``np.cross`` (the same
    products and differences), without its axis handling, which costs more than the arithmetic on meshes.

    Parameters
    ----------
    a, b : np.ndarray (..., 3)

    Returns
    -------
    np.ndarray (..., 3)
    """
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.result_type(a, b))
    np.subtract(a[..., 1] * b[..., 2], a[..., 2] * b[..., 1], out=out[..., 0])
    np.subtract(a[..., 2] * b[..., 0], a[..., 0] * b[..., 2], out=out[..., 1])
    np.subtract(a[..., 0] * b[..., 1], a[..., 1] * b[..., 0], out=out[..., 2])
    return out


def _orientation(R: np.ndarray) -> np.ndarray:
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise GeometryError(f"`R_body_to_camera` must be a 3x3 proper rotation, got {R!r}")
    return R


def _box_down(sub: np.ndarray, h: int, w: int) -> np.ndarray:
    """Mean over each ``ss x ss`` block of a float32 sub-pixel image (exact area average, C speed)."""
    return cv2.resize(sub, (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)


@dataclass(frozen=True)
class Raster:
    """Face-index buffer of :func:`rasterise`.

    Attributes
    ----------
    buf
        ``(h * ss, w * ss)`` int32: 1 + index of the face seen at each sub-pixel (0: sky).
    r0, c0, h, w
        The buffer covers pixels ``r0 .. r0 + h - 1``, ``c0 .. c0 + w - 1``.
    normals, mu
        Unit face normals (camera frame) and ``mu = n . e`` toward the camera, per face.
    """

    buf: np.ndarray
    r0: int
    c0: int
    h: int
    w: int
    normals: np.ndarray
    mu: np.ndarray


def rasterise(Xc: np.ndarray, F: np.ndarray, camera: object, ss: int, exact: bool = True) -> Raster | None:
    """Painter's-algorithm face-index buffer of the mesh (camera-frame vertices ``Xc``) at ``ss`` x the pixels.

    ``None`` when the projected mesh misses the frame.  Front-facing faces are filled
    far to near (centroid depth) with ``cv2.fillConvexPoly``, then with ``exact`` the fill's
    half-sub-pixel dilation is undone (:func:`_exact_edges`, module docstring).
    """
    rows, cols = camera.shape  # type: ignore[attr-defined]
    f = camera.focal_px  # type: ignore[attr-defined]
    r0, c0 = camera.principal_point_rc  # type: ignore[attr-defined]
    rc = np.stack([r0 + f * Xc[:, 1] / Xc[:, 2], c0 + f * Xc[:, 0] / Xc[:, 2]], axis=1)
    rmin, cmin = np.floor(rc.min(axis=0)).astype(int) - 2
    rmax, cmax = np.ceil(rc.max(axis=0)).astype(int) + 2
    rmin, cmin = max(rmin, 0), max(cmin, 0)
    rmax, cmax = min(rmax, rows - 1), min(cmax, cols - 1)
    if rmin > rmax or cmin > cmax:
        return None
    h, w = rmax - rmin + 1, cmax - cmin + 1
    # sub-pixel coordinates: pixel r covers [r-0.5, r+0.5]; sub-pixel centres at (r_ss+0.5)/ss-0.5
    sub = (rc - np.array([rmin, cmin]) + 0.5) * ss - 0.5
    v0, v1, v2 = (np.take(Xc, F[:, i], axis=0) for i in range(3))  # take: a faster gather than indexing
    n = cross_rows(v1 - v0, v2 - v0)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    cen = (v0 + v1 + v2) / 3.0
    e = -cen / np.linalg.norm(cen, axis=1, keepdims=True)
    mu = np.einsum("ij,ij->i", n, e)
    front = np.nonzero(mu > 0)[0]
    order = front[np.argsort(-cen[front, 2])]  # far to near
    buf = np.zeros((h * ss, w * ss), dtype=np.int32)
    pts = np.round(sub[:, ::-1] * 256.0).astype(np.int32)[F[order]]  # (x, y), 8 fractional bits
    n_fill = len(order)  # one fill per facet, far to near (map: no interpreted loop around the calls)
    fills = map(cv2.fillConvexPoly, repeat(buf, n_fill), list(pts), (order + 1).tolist(), repeat(cv2.LINE_8, n_fill), repeat(8, n_fill))
    deque(fills, maxlen=0)
    if exact:
        _exact_edges(buf, sub, F, cen[:, 2])
    return Raster(buf, int(rmin), int(cmin), int(h), int(w), n, mu)


def _edge_coefficients(sub: np.ndarray, F: np.ndarray) -> np.ndarray:
    """``(faces + 1, 3, 3)`` float32 ``(a, b, c)`` of each facet's edges: ``a r + b c + c`` is the signed distance
    (sub-pixels, positive inside) of the point ``(r, c)`` from the edge's line (row 0: the sky, never inside).
    ``sub``: vertex sub-pixel coordinates ``(row, col)``."""
    T = sub[F]  # (nf, 3, 2)
    P, Q = T, np.roll(T, -1, axis=1)
    length = np.maximum(np.hypot(Q[..., 0] - P[..., 0], Q[..., 1] - P[..., 1]), 1e-12)
    a = -(Q[..., 1] - P[..., 1]) / length
    b = (Q[..., 0] - P[..., 0]) / length
    c = -(a * P[..., 0] + b * P[..., 1])
    area = (T[:, 1, 0] - T[:, 0, 0]) * (T[:, 2, 1] - T[:, 0, 1]) - (T[:, 2, 0] - T[:, 0, 0]) * (T[:, 1, 1] - T[:, 0, 1])
    sgn = np.where(area < 0, -1.0, 1.0)[:, None]
    out = np.full((len(F) + 1, 3, 3), -1.0, np.float32)  # flattened to (faces + 1, 9) by the caller
    out[1:] = (np.stack([a, b, c], axis=2) * sgn[:, :, None]).astype(np.float32)
    out[0, :, :2] = 0.0
    return out


def _contains(coef: np.ndarray, label: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Whether facet ``label - 1`` (``label`` 0: sky, never) contains the sub-pixel centres ``(r, c)`` (edges included,
    to 1e-3 sub-pixel: float32 distances of coordinates up to a few thousand are good to ~3e-4).  ``coef``:
    ``(faces + 1, 9)``, each coefficient gathered from its own contiguous column."""
    cols = np.ascontiguousarray(coef.T)
    ok = None
    for i in range(3):
        a, b, d = (np.take(cols[3 * i + j], label) for j in range(3))
        e = a * r + b * c + d >= -1e-3
        ok = e if ok is None else ok & e
    return ok


_RING1 = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
_RING2 = [(dr, dc) for dr in (-2, -1, 0, 1, 2) for dc in (-2, -1, 0, 1, 2) if max(abs(dr), abs(dc)) == 2]
_PAD = 2  # the widest ring


def _nearest_containing(padded, coef, depth, flat, rc, own, ring):  # type: ignore[no-untyped-def]
    """Label of the nearest facet (``depth``, per label) drawn at offsets ``ring`` of each sub-pixel that contains
    its centre (``rc``: float32 rows and columns); -1 where none does.  ``padded``: the buffer edge-padded by
    ``_PAD`` (a neighbour beyond the edge is the edge's sub-pixel), ``flat`` the sub-pixels' indices in it.  Only
    the neighbours' labels other than ``own`` (the sub-pixel's, known not to contain it), the sky and a label
    already met earlier in the ring are tested (the first of equally near candidates wins either way)."""
    w = padded.shape[1]
    cand = np.stack([np.take(padded, flat + (dr * w + dc)) for dr, dc in ring])  # (ring, sub-pixels)
    test = (cand > 0) & (cand != own)
    for j in range(1, len(ring)):
        for i in range(j):
            test[j] &= cand[j] != cand[i]
    jj, ii = np.nonzero(test)
    lab = cand[jj, ii]
    ok = _contains(coef, lab, rc[0][ii], rc[1][ii])
    key = np.full(cand.shape, np.inf)
    key[jj[ok], ii[ok]] = depth[lab[ok]]
    best = np.argmin(key, axis=0)
    i = np.arange(own.size)
    return np.where(np.isfinite(key[best, i]), cand[best, i], -1)


def _exact_edges(buf: np.ndarray, sub: np.ndarray, F: np.ndarray, depth: np.ndarray) -> None:
    """Every sub-pixel takes the nearest facet that contains its centre (in place): the painter's buffer with
    each facet's half-sub-pixel dilation undone, on the outline and between facets alike.

    Only sub-pixels on a label boundary can be wrong, and only those outside their own facet are
    resolved: among the facets drawn in their 3 x 3, then 5 x 5 neighbourhood, the nearest (centroid
    depth, the painter's order) containing the centre; none on the outline (a sky 4-neighbour): sky;
    none inside the figure: kept.  Between facets the painter's dilation lets every nearer facet
    overlap its farther neighbour by half a sub-pixel, which shifts the shading pattern of a body seen
    at high phase toward the Sun (the nearer facets, toward the disc centre, are the darker ones of
    the lit side)."""
    rr, cc = np.nonzero(boundary_mask(buf) & (buf > 0))
    if rr.size == 0:
        return
    coef = np.ascontiguousarray(_edge_coefficients(sub, F).reshape(-1, 9))
    own = buf[rr, cc]
    out = ~_contains(coef, own, rr.astype(np.float32), cc.astype(np.float32))
    rr, cc, own = rr[out], cc[out], own[out]
    dep = np.concatenate([[np.inf], depth])
    padded = np.pad(buf, _PAD, mode="edge")  # the neighbours of the unchanged buffer, read flat
    w = padded.shape[1]
    flat = (rr + _PAD) * w + (cc + _PAD)
    rc = np.stack([rr, cc]).astype(np.float32)
    new = _nearest_containing(padded, coef, dep, flat, rc, own, _RING1)
    far = np.nonzero(new < 0)[0]
    if far.size:
        new[far] = _nearest_containing(padded, coef, dep, flat[far], rc[:, far], own[far], _RING2)
    sky = np.zeros(rr.size, bool)
    for d in (w, -w, 1, -1):
        sky |= np.take(padded, flat + d) == 0
    buf[rr, cc] = np.where(new >= 0, new, np.where(sky, 0, own))


def shade(mu0: np.ndarray, mu: np.ndarray, reflectance: str) -> np.ndarray:
    """Radiance per unit albedo of faces with cosines ``mu0`` (Sun) and ``mu`` (camera); 0 where unlit or unseen."""
    if reflectance == "lommel-seeliger":
        rad = np.where(mu0 > 0, 2.0 * mu0 / np.maximum(mu0 + mu, 1e-12), 0.0)
    else:
        rad = np.maximum(mu0, 0.0)
    return np.where(mu > 0, rad, 0.0)


@dataclass(frozen=True)
class _SunView:
    """A pinhole far along the Sun direction (``rasterise``'s camera interface): nearly orthographic."""

    focal_px: float
    shape: tuple[int, int]
    principal_point_rc: tuple[float, float]


_SHADOWS = IdentityCache(maxsize=8)


def shadow_fractions(vertices: np.ndarray, faces: np.ndarray, sun_body: np.ndarray, n_px: int = 1024) -> np.ndarray:
    """Lit fraction (0..1) of every facet: the share of its area the Sun sees (cast shadows).

    The mesh is rasterised as seen from the Sun (:func:`rasterise`, a pinhole
    1000 body radii away, ``n_px`` across the body); a facet's lit fraction is its sample count
    over the count its projected area predicts (above 0.8: 1, sampling noise).  Facets the Sun
    does not face get 0; facets expected to cover fewer than 6 samples keep 1 (unresolved).  Depends only on the Sun
    direction in the body frame, taken on a grid of ~0.25 deg cells (:data:`_SHADOW_GRID`) and computed at the
    cell's own direction: the map is a function of the cell alone, whatever direction reached it first (a map of
    the first direction seen in a cell would make a registration depend on the calls made before it), and cached
    per mesh.
    """
    V = np.asarray(vertices, dtype=float)
    F = np.asarray(faces, dtype=np.int64)
    cell = tuple(np.round(np.asarray(sun_body, dtype=float) / np.linalg.norm(sun_body) * _SHADOW_GRID).astype(int))
    # this mesh's facet normals (times twice the area) and its maps by Sun cell
    normals, cells = _SHADOWS.get((vertices, faces), lambda: (cross_rows(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), {}))
    if cell in cells:
        return cells[cell]
    sb = np.asarray(cell, dtype=float) / np.linalg.norm(cell)  # the cell's direction: the map depends on the cell alone
    rmax = float(np.linalg.norm(V, axis=1).max())
    L = 1000.0 * rmax
    z = -sb
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    Rs = np.stack([x, np.cross(z, x), z])
    f = L * 0.5 * n_px / (1.05 * rmax)
    cam = _SunView(f, (n_px, n_px), ((n_px - 1) / 2.0, (n_px - 1) / 2.0))
    # painter's fill only: lit fractions above 0.8 count as 1 anyway, and the exact buffer (1024^2 samples) did not
    # change the registrations (benchmarks/irregular_resample.py, 90 deg: median 0.088 px either way, 2026-11-26)
    ras = rasterise(np.einsum("ij,kj->ik", V, Rs) + [0.0, 0.0, L], F, cam, 1, exact=False)
    seen = np.bincount(ras.buf.ravel(), minlength=F.shape[0] + 1)[1:].astype(float) if ras is not None else np.zeros(F.shape[0])
    ns_ = np.einsum("ij,j->i", normals, sb)  # not BLAS: see register._normal_equations
    expected = 0.5 * np.maximum(ns_, 0.0) * (f / L) ** 2
    frac = np.clip(seen / np.maximum(expected, 1e-300), 0.0, 1.0)
    # sampling noise (a facet's edge samples go to it or its neighbour): near 1 is lit, and a facet
    # with fewer than 6 expected samples is unresolved
    frac = np.where((expected < 6.0) | (frac > 0.8), 1.0, frac)
    frac = np.where(ns_ > 0, frac, 0.0)
    if len(cells) >= _SHADOWS_PER_MESH:
        del cells[next(iter(cells))]
    cells[cell] = frac
    return frac


_SHADOWS_PER_MESH = 64
_SHADOW_GRID = 230.0  # cells of ~0.25 deg of Sun direction (1/230 rad)


def render_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    camera: object,
    R_body_to_camera: np.ndarray,
    t_camera: np.ndarray,
    sun_dir_camera: np.ndarray | None = None,
    options: MeshRenderOptions = MeshRenderOptions(),
) -> MeshRender:
    """Render a shaded mesh seen by a pinhole camera.

    Parameters
    ----------
    vertices, faces
        The mesh (km, body frame; faces wound counter-clockwise seen from outside).
    camera
        A :class:`jaxlimb.geometry.camera.Camera`.
    R_body_to_camera, t_camera
        Pose: ``X_c = R X_b + t`` (``t``: body centre in the camera frame, km).
    sun_dir_camera
        Unit vector from the body toward the Sun (camera frame); ``None`` = zero
        phase (the Sun behind the camera).
    options
        Rendering options.
    """
    R, t, s, headlight = _pose_and_sun(R_body_to_camera, t_camera, sun_dir_camera)
    V = np.asarray(vertices, dtype=float)
    F = np.asarray(faces, dtype=np.int64)
    Xc = V @ R.T + t
    if np.any(Xc[:, 2] <= 0):
        raise GeometryError("part of the mesh is behind the camera (z <= 0)")
    rows, cols = camera.shape  # type: ignore[attr-defined]
    f = camera.focal_px  # type: ignore[attr-defined]
    r0, c0 = camera.principal_point_rc  # type: ignore[attr-defined]
    center = np.array([r0 + f * t[1] / t[2], c0 + f * t[0] / t[2]])

    image = np.full((rows, cols), float(options.background))
    coverage = np.zeros((rows, cols))
    ras = rasterise(Xc, F, camera, options.supersample)
    if ras is not None:
        n, mu = ras.normals, ras.mu
        mu0 = mu if headlight else np.einsum("ij,j->i", n, s)
        rad = shade(mu0, mu, options.reflectance) * options.albedo
        if options.cast_shadows and not headlight:
            rad = rad * shadow_fractions(V, F, R.T @ s)
        lut = np.concatenate([[0.0], rad]).astype(np.float32)
        block = _box_down(lut[ras.buf], ras.h, ras.w)
        cblock = _box_down((ras.buf > 0).astype(np.float32), ras.h, ras.w)
        win = (slice(ras.r0, ras.r0 + ras.h), slice(ras.c0, ras.c0 + ras.w))
        image[win] = options.background * (1.0 - cblock) + block
        coverage[win] = cblock
    if options.noise_sigma > 0:
        image = image + np.random.default_rng(options.seed).normal(0.0, options.noise_sigma, image.shape)
    if options.quantize_bits is not None:
        image = np.clip(np.round(image), 0, 2**options.quantize_bits - 1)
    return MeshRender(image=image, center_rc=center, coverage=coverage)


def _pose_and_sun(R_body_to_camera: np.ndarray, t_camera: np.ndarray,
                  sun_dir_camera: np.ndarray | str | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """:func:`render_mesh`'s pose and unit Sun direction, checked, and whether the light is the ``"headlight"``
    (the Sun behind the camera also for ``None``)."""
    R = _orientation(R_body_to_camera)
    t = np.asarray(t_camera, dtype=float).reshape(3)
    if not np.all(np.isfinite(t)) or t[2] <= 0:
        raise GeometryError(f"`t_camera` must be finite with z > 0, got {t!r}")
    headlight = isinstance(sun_dir_camera, str) and sun_dir_camera == "headlight"
    s = -t / np.linalg.norm(t) if (sun_dir_camera is None or headlight) else np.asarray(sun_dir_camera, dtype=float).reshape(3)
    if not (np.all(np.isfinite(s)) and abs(np.linalg.norm(s) - 1.0) < 1e-3):
        raise GeometryError(f"`sun_dir_camera` must be a unit vector, got {s!r}")
    s = s / np.linalg.norm(s)
    return R, t, s, headlight


def look_at_rotation(view_dir_body: np.ndarray, up_body: np.ndarray | None = None, roll_rad: float = 0.0) -> np.ndarray:
    """Body->camera rotation for a camera looking along ``-view_dir_body`` at the body centre.

    ``view_dir_body`` is the unit vector from the body centre toward the camera
    (body frame).  The camera ``+y`` (image rows) is chosen perpendicular to it,
    from ``up_body`` (default: body ``+z``, or ``+x`` if nearly parallel), then
    rolled by ``roll_rad`` about the boresight.
    """
    d = np.asarray(view_dir_body, dtype=float)
    d = d / np.linalg.norm(d)
    z = -d
    up = np.array([0.0, 0.0, 1.0]) if up_body is None else np.asarray(up_body, dtype=float)
    if abs(up @ z) > 0.99 * np.linalg.norm(up):
        up = np.array([1.0, 0.0, 0.0])
    y = up - (up @ z) * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    R = np.stack([x, y, z])  # rows: camera axes in body frame -> body->camera
    c, sn = math.cos(roll_rad), math.sin(roll_rad)
    Rz = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ R


__all__ = [
    "MeshRender", "MeshRenderOptions", "Raster", "cross_rows", "look_at_rotation", "rasterise", "render_mesh", "shade",
    "shadow_fractions",
]  # fmt: skip
