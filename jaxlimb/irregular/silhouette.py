"""Projected silhouettes of a mesh, and the figure of the body in an image.

Template silhouettes (Sec. 3.2 of Wu et al.)
--------------------------------------------
The paper projects every vertex (Eq. 9), links the two images of every edge in
a binary image and traces the outer contour with Moore-neighbour tracing.  We
draw only the edges that can lie on the outline -- the *contour-generator*
edges, whose two adjacent faces face opposite ways (one front-facing, one
back-facing; for a closed mesh the outer boundary of the projected figure is
made of such edges) -- in one ``cv2.polylines`` call, trace the outer contour
with ``cv2.findContours`` (Suzuki-Abe border following, which on a binary image
visits the same 8-connected boundary as Moore-neighbour tracing) and fill it.
Interior fold lines do not matter because only the *external* contour is kept;
a see-through hole in the figure (a torus) would be filled -- a documented
limitation, irrelevant for asteroids and moons.

For a lit figure (phase > 0) the same construction is applied to the set of
faces that are both front-facing and lit (``n.v > 0`` and ``n.s > 0``): its
outline is made of the lit limb and the terminator.  Cast shadows are ignored.

Pixel accuracy: a drawn edge covers the pixels whose centres lie within half a
pixel of it on either side, so the polygon through the centres of the outer
contour pixels follows the true outline without bias; moments of that polygon
(Green's theorem) are used for templates (see :mod:`.features`).

Figure of the body in an image (Sec. 4)
---------------------------------------
Threshold (Otsu's threshold on the grey levels unless given), keep the largest
8-connected component, fill its holes.  The threshold sits between the
background and the body levels, so a partly covered edge pixel counts when more
than about half of it is body: pixel-count moments of the mask are unbiased.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .._identity_cache import IdentityCache
from ..errors import GeometryError, ImageContentError, NoBodyError, TooBigError, TooSmallError
from .mesh import Mesh, edge_faces, face_normals

_SHIFT = 4  # fractional bits for OpenCV drawing


@dataclass(frozen=True)
class MeshTopology:
    """Precomputed edge adjacency and face normals of a :class:`Mesh`."""

    vertices: np.ndarray  # (N, 3)
    faces: np.ndarray  # (M, 3)
    normals: np.ndarray  # (M, 3) unit outward
    offsets: np.ndarray  # (M,) n . v0 (plane offsets)
    edges: np.ndarray  # (E, 2) vertex indices, as traversed by adjacent[:, 0]
    adjacent: np.ndarray  # (E, 2) faces
    third: np.ndarray  # (E, 2) the vertex opposite the edge in each adjacent face


_TOPOLOGY = IdentityCache(maxsize=2)


def cached_topology(mesh: Mesh) -> MeshTopology:
    """:func:`mesh_topology` of ``mesh``, computed once for the last meshes asked about (registration and the
    outline refinement ask for it at every iteration).

    Parameters
    ----------
    mesh : Mesh
        A validated mesh (kept by identity).

    Returns
    -------
    MeshTopology
    """
    return _TOPOLOGY.get((mesh,), lambda: mesh_topology(mesh))


def mesh_topology(mesh: Mesh) -> MeshTopology:
    """Edge/face adjacency used to find contour-generator edges quickly.

    Parameters
    ----------
    mesh : Mesh
        A closed, consistently wound mesh.

    Returns
    -------
    MeshTopology
        Vertices, faces, unit outward normals, plane offsets, edges, adjacent faces and opposite vertices.
    """
    v, f = mesh.vertices, mesh.faces
    edges, adj = edge_faces(f)
    n = face_normals(v, f)
    off = np.einsum("ij,ij->i", n, v[f[:, 0]])
    third = np.empty_like(adj)
    for k in range(2):
        ff = f[adj[:, k]]
        is_a = ff == edges[:, :1]
        is_b = ff == edges[:, 1:2]
        third[:, k] = ff[~(is_a | is_b)]
    return MeshTopology(v, f, n, off, edges, adj, third)


def visible_faces(
    topo: MeshTopology, camera_pos_body: np.ndarray, sun_dir_body: np.ndarray | None = None
) -> np.ndarray:
    """Boolean per face: front-facing from ``camera_pos_body`` (and lit, if a Sun direction is given).

    Front-facing: ``n . (c - v0) > 0`` (perspective, exact for planar faces).
    Lit: ``n . s > 0`` with ``s`` the unit direction from the body toward the Sun.

    Parameters
    ----------
    topo : MeshTopology
        The mesh.
    camera_pos_body : np.ndarray (3,)
        Camera position ``c`` in the body frame (km).
    sun_dir_body : np.ndarray (3,), optional
        Direction toward the Sun, body frame.

    Returns
    -------
    np.ndarray (M,) of bool
    """
    # einsum, not BLAS: a threaded matrix-vector product leaves OpenBLAS threads spinning (register._normal_equations)
    flag = np.einsum("ij,j->i", topo.normals, np.asarray(camera_pos_body, dtype=float)) - topo.offsets > 0.0
    if sun_dir_body is not None:
        flag &= np.einsum("ij,j->i", topo.normals, np.asarray(sun_dir_body, dtype=float)) > 0.0
    return flag


def outline_edges(topo: MeshTopology, face_flag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edges between a flagged and an unflagged face.

    Parameters
    ----------
    topo : MeshTopology
        The mesh.
    face_flag : np.ndarray (M,) of bool
        Per face, e.g. :func:`visible_faces`.

    Returns
    -------
    edges : np.ndarray (K, 2) of int
        Vertex indices oriented so that the flagged face traverses them ``edges[:,0] -> edges[:,1]``.
    inner_third : np.ndarray (K,) of int
        The third vertex of the flagged face (which lies on the inner side).
    """
    fa = face_flag[topo.adjacent[:, 0]]
    fb = face_flag[topo.adjacent[:, 1]]
    sel_a = fa & ~fb
    sel_b = fb & ~fa
    e = np.concatenate([topo.edges[sel_a], topo.edges[sel_b][:, ::-1]], axis=0)
    t = np.concatenate([topo.third[sel_a, 0], topo.third[sel_b, 1]], axis=0)
    return e, t


def _to_cv_points(rc: np.ndarray) -> np.ndarray:
    """(row, col) float -> OpenCV (x=col, y=row) int32 with _SHIFT fractional bits."""
    xy = rc[..., ::-1] * (1 << _SHIFT)
    return np.round(xy).astype(np.int32)


def fill_outline(segments_rc: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Draw segments (row, col), trace the outer contours and fill them.

    Parameters
    ----------
    segments_rc : np.ndarray (K, 2, 2)
        Segment end points, px (row, col).
    shape : (int, int)
        Image shape.

    Returns
    -------
    mask
        ``uint8`` figure (1 inside), ``shape``.
    contours
        External contours as returned by ``cv2.findContours`` (``(n, 1, 2)`` int32
        ``(x=col, y=row)`` pixel centres).
    """
    img = np.zeros(shape, dtype=np.uint8)
    if segments_rc.shape[0] == 0:
        return img, []
    cv2.polylines(img, _to_cv_points(segments_rc), isClosed=False, color=1, thickness=1, lineType=cv2.LINE_8, shift=_SHIFT)
    contours, _ = cv2.findContours(img, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(img, contours, -1, color=1, thickness=cv2.FILLED)
    return img, list(contours)


def render_silhouette(
    topo: MeshTopology, R_body_to_camera: np.ndarray, t_camera: np.ndarray, focal_px: float, principal_rc: tuple[float, float],
    shape: tuple[int, int], sun_dir_camera: np.ndarray | None = None,
) -> tuple[np.ndarray, list[np.ndarray]]:  # fmt: skip
    """Binary projected figure of the mesh (optionally only its lit part).

    The mesh is placed with ``X_c = R X_b + t`` (body centre at ``t``), projected
    with the pinhole of Eq. (9); see the module docstring for the construction.

    Parameters
    ----------
    topo : MeshTopology
        The mesh.
    R_body_to_camera, t_camera : np.ndarray (3, 3), (3,)
        Pose: rotation and body centre in the camera frame (km).
    focal_px, principal_rc : float, (float, float)
        Focal length (px) and principal point (row, col).
    shape : (int, int)
        Image shape.
    sun_dir_camera : np.ndarray (3,), optional
        Unit direction toward the Sun, camera frame: only the lit faces are drawn.

    Returns
    -------
    mask, contours
        As :func:`fill_outline`.

    Raises
    ------
    GeometryError
        Part of the mesh is behind the camera.
    """
    R = np.asarray(R_body_to_camera, dtype=float)
    t = np.asarray(t_camera, dtype=float)
    cam_body = -R.T @ t
    sun_body = None if sun_dir_camera is None else R.T @ np.asarray(sun_dir_camera, dtype=float)
    flag = visible_faces(topo, cam_body, sun_body)
    edges, _ = outline_edges(topo, flag)
    used = np.unique(edges)
    Xc = topo.vertices[used] @ R.T + t
    if np.any(Xc[:, 2] <= 0):
        raise GeometryError("part of the mesh is behind the camera (z <= 0); move the camera away from the body")
    rc = np.empty((topo.vertices.shape[0], 2))
    rc[used, 0] = principal_rc[0] + focal_px * Xc[:, 1] / Xc[:, 2]
    rc[used, 1] = principal_rc[1] + focal_px * Xc[:, 0] / Xc[:, 2]
    return fill_outline(rc[edges], shape)


def fill_triangles_exact(rc_tri: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Reference rasteriser: union of triangles drawn one by one (slow; for tests).

    Parameters
    ----------
    rc_tri : np.ndarray (F, 3, 2)
        Triangle corners, px (row, col).
    shape : (int, int)
        Image shape.

    Returns
    -------
    np.ndarray of uint8
        1 inside any triangle.
    """
    img = np.zeros(shape, dtype=np.uint8)
    for tri in _to_cv_points(rc_tri):
        cv2.fillConvexPoly(img, tri, 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return img


# --------------------------------------------------------------------------- image figure
@dataclass(frozen=True)
class SegmentOptions:
    """Options of :func:`segment_body`.

    Parameters
    ----------
    threshold
        Grey-level threshold; ``None`` = Otsu's threshold computed on the image.
    min_area_px
        Smallest figure accepted (:class:`~jaxlimb.errors.TooSmallError` below).
    allow_border
        Accept a figure touching the image border (cut figures bias every centre
        estimate, so by default :class:`~jaxlimb.errors.TooBigError` is raised).
    """

    threshold: float | None = None
    min_area_px: int = 50
    allow_border: bool = False


def otsu_threshold(image: np.ndarray, bins: int = 256, max_samples: int = 250_000) -> float:
    """Otsu's threshold of a float image (maximises the between-class variance).

    Large images are subsampled on a regular grid (at most ``max_samples`` pixels)
    for the histogram; the threshold is a grey level, so this changes it only by
    sampling noise.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Grey image.
    bins, max_samples : int
        Histogram bins and the most pixels sampled.

    Returns
    -------
    float
        Grey level between the two classes.

    Raises
    ------
    NoBodyError
        Constant image.
    """
    a = np.asarray(image, dtype=float)
    step = max(1, int(math.ceil(math.sqrt(a.size / max_samples))))
    x = a[::step, ::step].ravel()
    lo, hi = float(a.min()), float(a.max())
    if not hi > lo:
        raise NoBodyError(f"the image is constant (all pixels = {lo:g}): no body")
    q = np.minimum(((x - lo) * (bins / (hi - lo))).astype(np.int64), bins - 1)
    hist = np.bincount(q, minlength=bins).astype(float)
    edges = lo + (hi - lo) * np.arange(bins + 1) / bins
    centers = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    s0 = np.cumsum(hist * centers)
    m0 = s0 / np.maximum(w0, 1)
    m1 = (s0[-1] - s0) / np.maximum(w1, 1)
    between = w0 * w1 * (m0 - m1) ** 2
    k = int(np.argmax(between[:-1]))
    return float(edges[k + 1])


def segment_body(image: np.ndarray, options: SegmentOptions = SegmentOptions()) -> tuple[np.ndarray, float]:
    """Binary figure of the body: threshold, largest 8-connected component, holes filled.

    Raises the errors of :func:`segment_components` (not a finite 2-D image; a constant
    image, a figure below ``min_area_px`` or touching the border).

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Grey image.
    options : SegmentOptions
        Threshold, smallest area, border policy.

    Returns
    -------
    mask : np.ndarray (rows, cols) of uint8
        1 inside the figure.
    threshold : float
        The grey level used.
    """
    return segment_components(image, options)[:2]


def segment_components(image: np.ndarray, options: SegmentOptions = SegmentOptions()):  # type: ignore[no-untyped-def]
    """:func:`segment_body`'s ``(mask, threshold)`` and the labels and stats of every component above the
    threshold (``cv2.connectedComponentsWithStats``, 8-connected), for callers that keep more than the largest.

    Parameters
    ----------
    image, options
        As :func:`segment_body`.

    Returns
    -------
    mask, threshold, labels, stats
        The figure, the grey level, the component label image and the ``(n, 5)`` OpenCV stats (row 0: background).

    Raises
    ------
    ImageContentError
        Not a finite 2-D image.
    NoBodyError, TooSmallError, TooBigError
        Constant image / figure below ``min_area_px`` / figure touching the border.
    """
    img = np.asarray(image, dtype=float)
    if img.ndim != 2 or min(img.shape) < 2:
        raise ImageContentError(f"image must be a 2-D array of at least 2x2, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ImageContentError("image contains non-finite values")
    thr = otsu_threshold(img) if options.threshold is None else float(options.threshold)
    binary = (img > thr).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    if n <= 1:
        raise NoBodyError(f"no pixel above the threshold {thr:g}: no body")
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    comp = (labels == k).astype(np.uint8)
    contours, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    mask = np.zeros_like(comp)
    cv2.drawContours(mask, contours, -1, color=1, thickness=cv2.FILLED)
    area = int(mask.sum())
    if area < options.min_area_px:
        raise TooSmallError(f"body figure has {area} px, below `min_area_px` = {options.min_area_px}")
    if not options.allow_border and (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any()):
        raise TooBigError("the body figure touches the image border; its centre cannot be located reliably")
    return mask, thr, labels, stats


def figure_center(mask: np.ndarray) -> np.ndarray:
    """Figure centre (FC baseline): centroid ``(row, col)`` of a binary figure.

    Parameters
    ----------
    mask : np.ndarray (rows, cols)
        Binary figure.

    Returns
    -------
    np.ndarray (2,)
        Centroid, px (row, col).
    """
    m = cv2.moments(np.ascontiguousarray(mask, dtype=np.uint8), binaryImage=True)
    if m["m00"] <= 0:
        raise NoBodyError("empty figure: no figure centre")
    return np.array([m["m01"] / m["m00"], m["m10"] / m["m00"]])


def figure_extents(mask: np.ndarray, axes_rc: np.ndarray, contours: list[np.ndarray] | None = None) -> np.ndarray:
    """``max`` of a figure's pixel centres along each unit (row, col) direction of ``axes_rc``.

    The maximum of a linear function over the pixels is attained on the outer contours
    (at an end of a straight run: ``CHAIN_APPROX_SIMPLE`` keeps those), so only they are
    visited.

    Parameters
    ----------
    mask : np.ndarray (rows, cols)
        Binary figure.
    axes_rc : np.ndarray (k, 2)
        Unit directions (row, col).
    contours : list of np.ndarray, optional
        ``cv2.findContours`` external contours of ``mask`` (e.g. from :func:`fill_outline`), to save tracing them again.

    Returns
    -------
    np.ndarray (k,)
        Largest projection (px) of the figure on each direction.
    """
    if contours is None:
        contours, _ = cv2.findContours(np.ascontiguousarray(mask, dtype=np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not len(contours):
        raise NoBodyError("empty figure: no extents")
    xy = np.concatenate([c.reshape(-1, 2) for c in contours]).astype(float)
    return (xy[:, ::-1] @ np.asarray(axes_rc, dtype=float).T).max(axis=0)


def brightness_center(image: np.ndarray, mask: np.ndarray | None = None, background: float | None = None) -> np.ndarray:
    """Brightness centre (BC baseline): intensity-weighted centroid ``(row, col)``.

    Weights are ``max(I - background, 0)`` over ``mask`` (all pixels if ``None``);
    ``background`` defaults to the median of a ring of pixels around the mask's
    bounding box (or 0 without a mask).

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Grey image.
    mask : np.ndarray (rows, cols), optional
        Figure.
    background : float, optional
        Background level (DN).

    Returns
    -------
    np.ndarray (2,)
        Centroid, px (row, col).
    """
    img = np.asarray(image, dtype=float)
    r0, c0 = 0, 0
    if mask is not None:
        rr, cc = np.nonzero(np.asarray(mask).any(axis=1))[0], np.nonzero(np.asarray(mask).any(axis=0))[0]
        if rr.size == 0:
            raise NoBodyError("empty figure: no brightness centre")
        if background is None:
            pad = 4
            R0, R1 = max(rr[0] - pad, 0), min(rr[-1] + pad, img.shape[0] - 1)
            C0, C1 = max(cc[0] - pad, 0), min(cc[-1] + pad, img.shape[1] - 1)
            win, wm = img[R0 : R1 + 1, C0 : C1 + 1], np.asarray(mask)[R0 : R1 + 1, C0 : C1 + 1]
            background = float(np.median(win[wm == 0])) if (wm == 0).any() else 0.0
        r0, c0 = int(rr[0]), int(cc[0])
        img = img[r0 : int(rr[-1]) + 1, c0 : int(cc[-1]) + 1]
        m = np.asarray(mask)[r0 : int(rr[-1]) + 1, c0 : int(cc[-1]) + 1] > 0
    else:
        m = np.ones(img.shape, dtype=bool)
    w = np.maximum(img - (background or 0.0), 0.0) * m
    s = w.sum()
    if not s > 0:
        raise NoBodyError("no pixel brighter than the background: no brightness centre")
    return np.array([(w.sum(axis=1) @ np.arange(w.shape[0])) / s + r0, (w.sum(axis=0) @ np.arange(w.shape[1])) / s + c0])


__all__ = [
    "MeshTopology", "SegmentOptions", "brightness_center", "figure_center", "figure_extents", "fill_outline",
    "fill_triangles_exact", "mesh_topology", "otsu_threshold", "outline_edges", "render_silhouette", "segment_body",
    "segment_components", "visible_faces",
]  # fmt: skip
