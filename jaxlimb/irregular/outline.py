"""The frozen outline of a soft-silhouette fit: limb pieces, band pixels and their nearest pieces.

For a pose, the outline edges are those between a *visible* face and a non-visible one, visible meaning
front-facing (``n.v > 0``) and, with a Sun direction, lit (``n.s > 0``): the lit silhouette.  Edges are
split into pieces of ``_PIECE_PX``; only pieces on the *outer* boundary of the (lit) figure are kept (tested
on the figure rasterised ``_TEST_SUPERSAMPLE`` x).  Of those, only **limb** pieces (whose other face is
back-facing) are fitted: the terminator of a Lommel-Seeliger surface is a soft, albedo- and slope-dependent
ramp, not a sigmoid edge.  Pixels near a dangling piece end (a T-junction where one limb passes behind
another) are dropped.  The projection is the pinhole of Eq. (1)-(4) of Wu et al.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from ..errors import GeometryError
from .silhouette import outline_edges, render_silhouette, visible_faces

_PIECE_PX = 2.0  # outline edges are split into pieces of at most this length (px)
# a piece is on the outer boundary when the point _TEST_OFFSET_PX outside its midpoint lies outside the figure
# rasterised _TEST_SUPERSAMPLE x (folds closer than that to the outline count as outline, harmlessly)
_TEST_SUPERSAMPLE = 8
_TEST_OFFSET_PX = 0.3
_N_NEIGHBOURS = 4  # candidate outline pieces kept per pixel


def _outline_pieces(rc, V, edges, third, limb, fig, lo, ss):  # type: ignore[no-untyped-def]
    """Every outline edge split into pieces of <= ``_PIECE_PX`` (3-D interpolation projects onto the same
    straight line); only the pieces on the outer boundary of the figure ``fig`` (rasterised ``ss`` x) are kept.  Returns the
    3-D end points and third vertex ``PA, PB, PC``, the image end points ``pa, pb`` and the limb flag."""
    a2, b2 = rc[edges[:, 0]], rc[edges[:, 1]]
    L = np.linalg.norm(b2 - a2, axis=1)
    npieces = np.maximum(np.ceil(L / _PIECE_PX).astype(int), 1)
    parent = np.repeat(np.arange(edges.shape[0]), npieces)
    start = np.concatenate([np.arange(n) / n for n in npieces])
    stop = np.concatenate([np.arange(1, n + 1) / n for n in npieces])
    VA, VB = V[edges[parent, 0]], V[edges[parent, 1]]
    PA = VA + start[:, None] * (VB - VA)
    PB = VA + stop[:, None] * (VB - VA)
    PC = V[third[parent]]
    limb = limb[parent]
    pa = a2[parent] + start[:, None] * (b2 - a2)[parent]
    pb = a2[parent] + stop[:, None] * (b2 - a2)[parent]
    pc = rc[third[parent]]
    e = pb - pa
    nrm = np.stack([-e[:, 1], e[:, 0]], axis=1)
    side = np.sign(np.sum(nrm * (pc - pa), axis=1))
    nrm = -side[:, None] * nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    mid = (0.5 * (pa + pb) + _TEST_OFFSET_PX * nrm - lo + 0.5) * ss - 0.5
    ir = np.clip(np.round(mid[:, 0]).astype(int), 0, fig.shape[0] - 1)
    ic = np.clip(np.round(mid[:, 1]).astype(int), 0, fig.shape[1] - 1)
    outer = fig[ir, ic] == 0
    return PA[outer], PB[outer], PC[outer], pa[outer], pb[outer], limb[outer]


def _band_pixels(PA, PB, pa, pb, limb, lo, hi, band):  # type: ignore[no-untyped-def]
    """Pixels within ``band`` of a limb piece, away from dangling piece ends (T-junctions, hidden cuts: no
    sign is reliable there); with the KD tree of points sampled along the pieces (<= 0.5 px apart) and
    each point's piece index."""
    L = np.linalg.norm(pb - pa, axis=1)
    ns = np.maximum(np.ceil(L / 0.5).astype(int), 1)
    seg_id = np.repeat(np.arange(pa.shape[0]), ns + 1)
    frac = np.concatenate([np.linspace(0.0, 1.0, n + 1) for n in ns])
    pts = pa[seg_id] + frac[:, None] * (pb - pa)[seg_id]
    tree = cKDTree(pts)
    r_idx, c_idx = np.mgrid[lo[0] : hi[0] + 1, lo[1] : hi[1] + 1]
    pix_all = np.stack([r_idx.ravel(), c_idx.ravel()], axis=1).astype(float)
    d1, i1 = tree.query(pix_all, k=1, distance_upper_bound=band)
    keep = np.isfinite(d1)
    keep[keep] &= limb[seg_id[i1[keep]]]
    ends = np.concatenate([PA, PB], axis=0)
    _, inv, cnt = np.unique(np.round(ends, 9), axis=0, return_inverse=True, return_counts=True)
    dangling = cnt[inv.ravel()] == 1
    if np.any(dangling):
        end2d = np.concatenate([pa, pb], axis=0)[dangling]
        dd, _ = cKDTree(end2d).query(pix_all[keep], k=1)
        kidx = np.nonzero(keep)[0]
        keep[kidx[dd <= band]] = False
    return pix_all[keep], tree, seg_id


def _nearest_pieces(pix, tree, seg_id, kn: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The ``kn`` distinct pieces nearest each pixel, in order of proximity (the nearest repeated when fewer)."""
    _, ik = tree.query(pix, k=min(6 * kn, tree.n))
    segs = seg_id[np.atleast_2d(ik)]
    first = np.ones_like(segs, dtype=bool)  # first occurrence of each piece id per row
    for j in range(1, segs.shape[1]):
        first[:, j] = np.all(segs[:, :j] != segs[:, j : j + 1], axis=1)
    order = np.argsort(~first, axis=1, kind="stable")
    ranked = np.take_along_axis(segs, order, axis=1)
    nfirst = first.sum(axis=1)
    nbr = ranked[:, :kn].copy()
    short = nfirst < kn
    if np.any(short):
        for j in range(kn):
            m = short & (nfirst <= j)
            nbr[m, j] = ranked[m, 0]
    return nbr


def _padded(pieces, pix, val, nbr, min_sizes):  # type: ignore[no-untyped-def]
    """Pieces and pixels padded to size buckets (fewer recompilations); padded pixels get weight 0."""
    npx, ne = pix.shape[0], pieces[0].shape[0]
    bp, be = max(_bucket(npx), min_sizes[0]), max(_bucket(ne), min_sizes[1])
    pix_p = np.repeat(pix[:1], bp, axis=0)
    pix_p[:npx] = pix
    val_p = np.zeros(bp)
    val_p[:npx] = val
    nbr_p = np.zeros((bp, nbr.shape[1]), dtype=np.int64)
    nbr_p[:npx] = nbr
    weight = np.zeros(bp)
    weight[:npx] = 1.0

    def padv(X: np.ndarray) -> np.ndarray:
        out = np.repeat(X[:1], be, axis=0)
        out[:ne] = X
        return out

    return (*(padv(X) for X in pieces), pix_p, val_p, nbr_p, weight)


def outline_data(topo, camera, image, R, t, sun, band, min_sizes=(0, 0)):  # type: ignore[no-untyped-def]
    """Frozen outline at the pose ``(R, t)`` (module docstring), padded to at least ``min_sizes``; a
    :class:`~jaxlimb.errors.GeometryError` when part of the mesh is behind the camera.

    Parameters
    ----------
    topo, camera, image : MeshTopology, Camera, np.ndarray (rows, cols)
        Mesh topology (:func:`~.silhouette.mesh_topology`), the frame's camera and the frame.
    R, t, sun : np.ndarray (3, 3), (3,), (3,) or None
        Body-to-camera rotation, body centre (km, camera frame), unit Sun direction (camera frame).
    band, min_sizes : float, (int, int)
        Half-width (px) of the pixel band around the limb; smallest padded (pixel, piece) counts.

    Returns
    -------
    tuple or None
        ``(A, B, C, pix, val, nbr, weight)``: the limb pieces' 3-D end points and third vertices (body frame), the
        band pixels (row, col), their values, nearest pieces and weights (0: padding); ``None`` with too few.
    """
    f = float(camera.focal_px)
    pp = tuple(float(v) for v in camera.principal_point_rc)
    shape = image.shape
    cam_body = -R.T @ t
    sun_body = None if sun is None else R.T @ sun
    front = visible_faces(topo, cam_body)
    flag = front if sun_body is None else front & visible_faces(topo, cam_body, sun_body)
    edges, third = outline_edges(topo, flag)
    # other face of each outline edge: limb if it is back-facing
    fa, fb = topo.adjacent[:, 0], topo.adjacent[:, 1]
    sel_a = flag[fa] & ~flag[fb]
    sel_b = flag[fb] & ~flag[fa]
    other = np.concatenate([fb[sel_a], fa[sel_b]])
    limb = ~front[other]
    V = topo.vertices
    Xc = V @ R.T + t
    if np.any(Xc[:, 2] <= 0):
        raise GeometryError("refinement: part of the mesh is behind the camera")
    rc = np.stack([pp[0] + f * Xc[:, 1] / Xc[:, 2], pp[1] + f * Xc[:, 0] / Xc[:, 2]], axis=1)
    lo = np.floor(rc.min(axis=0)).astype(int) - int(band) - 3
    hi = np.ceil(rc.max(axis=0)).astype(int) + int(band) + 3
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, np.array(shape) - 1)
    if np.any(hi - lo < 4):
        return None
    win = (int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1))
    ss = _TEST_SUPERSAMPLE
    fig, _ = render_silhouette(topo, R, t, f * ss, ((pp[0] - lo[0] + 0.5) * ss - 0.5, (pp[1] - lo[1] + 0.5) * ss - 0.5),
                               (win[0] * ss, win[1] * ss), sun_dir_camera=None if sun is None else sun)  # fmt: skip
    PA, PB, PC, pa, pb, limb = _outline_pieces(rc, V, edges, third, limb, fig, lo, ss)
    if not np.any(limb):
        return None
    pix, tree, seg_id = _band_pixels(PA, PB, pa, pb, limb, lo, hi, band)
    if pix.shape[0] < 20:
        return None
    nbr = _nearest_pieces(pix, tree, seg_id, _N_NEIGHBOURS)
    val = image[pix[:, 0].astype(int), pix[:, 1].astype(int)]
    return _padded((PA, PB, PC), pix, val, nbr, min_sizes)



def _bucket(n: int) -> int:
    """The next power of two (at least 16)."""
    return int(2 ** math.ceil(math.log2(max(n, 16))))


__all__ = ["outline_data"]
