"""Triangle shape models: reading, validation, repair and hashing.

Wu et al. (Sec. 3.2) load an STL triangle mesh and use only its vertices ``V`` and edges ``E``.  This module reads
OBJ, STL (binary and ASCII) and PLY through :mod:`trimesh`, and the PDS-style plate tables (``v x y z`` / ``f i j k``
lines with **0-based** face indices, e.g. ``eros007790.tab``) with its own reader (both in :mod:`._mesh_files`).

Every mesh is validated before use (:func:`validate_mesh`):

* finite vertex coordinates, at least 4 vertices and 4 faces, indices in range;
* non-degenerate faces (repeated vertex index or area below ``degenerate_rel_area`` times the mean face area) --
  dropped when ``repair=True``, otherwise refused;
* closed (watertight): every undirected edge is shared by exactly two faces;
* consistently wound: the two faces sharing an edge traverse it in opposite directions -- repaired by
  breadth-first re-orientation over shared edges when ``repair=True``;
* outward normals: the signed volume ``sum(v0 . (v1 x v2)) / 6`` is positive -- an inverted mesh (negative
  volume) is flipped when ``repair=True``;
* a manifold surface: the faces around every vertex form one fan (two bodies touching at a vertex, a
  "bow-tie", are refused).

Open meshes are always refused: closing holes would invent geometry that moves the silhouette.  Before a file is
parsed, its declared face count (OBJ ``f`` lines, the STL/PLY/OFF headers, plate-table ``f`` lines) must be at most
:data:`MAX_FACES` and fit the memory available; OBJ indices are 1-based, so an index ``0`` is refused (a reader
would take it for the last vertex).  Failures raise :class:`jaxlimb.errors.MeshError`.

Coordinates are kept exactly as in the file (km, body-fixed frame).  The body centre is the **origin** of these
coordinates (docs/design.md), not the volume centroid.  No axis is re-labelled here: which axis is the pole only
matters for the view-sphere sampling, see :class:`jaxlimb.irregular.views.ViewSphereOptions` (``pole_axis``;
Celestia models such as ``thebe.obj``/``phobos.obj`` are y-up).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import MeshError
from ._mesh_files import TABLE_EXT, TRIMESH_EXT, declared_faces, read_table, read_trimesh

#: Most faces of a shape model jaxlimb reads: a 512-px template resolves ~10^5 faces, so a finer model only
#: costs memory and time (decimate it first).
MAX_FACES = 1_000_000
#: Memory per face while a mesh is read, validated and its templates built: about twice the peak measured
#: (564-622 B/face for phobos.obj and a 327 680-face sphere: ``python benchmarks/faults.py --only mesh``).
BYTES_PER_FACE = 1024


@dataclass(frozen=True)
class MeshOptions:
    """Options of :func:`load_mesh` / :func:`validate_mesh`.

    Parameters
    ----------
    repair
        Repair what can be repaired without inventing geometry (drop degenerate faces, fix inconsistent
        winding, flip an inverted mesh).  With ``False`` any such defect raises :class:`~jaxlimb.errors.MeshError`.
    degenerate_rel_area
        A face whose area is below this fraction of the mean face area is degenerate.
    """

    repair: bool = True
    degenerate_rel_area: float = 1e-10


@dataclass(frozen=True)
class Mesh:
    """A closed, outward-wound triangle mesh (km, body-fixed, origin = body centre).

    Attributes
    ----------
    vertices
        ``(N, 3)`` float64 vertex coordinates.
    faces
        ``(M, 3)`` int64 vertex indices, counter-clockwise seen from outside.
    repairs
        Human-readable list of repairs applied while loading (empty if none).
    source
        File name the mesh was read from (informational).
    """

    vertices: np.ndarray
    faces: np.ndarray
    repairs: tuple[str, ...] = field(default=())
    source: str = ""

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def max_radius(self) -> float:
        """Largest distance of a vertex from the origin (the body centre), km."""
        return float(np.sqrt((self.vertices**2).sum(axis=1)).max())

    @property
    def volume(self) -> float:
        """Signed volume (km^3); positive for outward normals."""
        return signed_volume(self.vertices, self.faces)

    @property
    def sha256(self) -> str:
        """Content hash, see :func:`mesh_hash`."""
        return mesh_hash(self)


# --------------------------------------------------------------------------- geometry helpers
def face_normals(vertices: np.ndarray, faces: np.ndarray, normalize: bool = True) -> np.ndarray:
    """Face normals ``(v1 - v0) x (v2 - v0)`` (outward for CCW faces), optionally unit.

    Parameters
    ----------
    vertices, faces, normalize : np.ndarray (N, 3), np.ndarray (M, 3) of int, bool
        Vertex coordinates, vertex indices of each face, and whether to return unit vectors.

    Returns
    -------
    np.ndarray (M, 3)
        Normals (length: twice the face area unless ``normalize``).
    """
    v0, v1, v2 = (vertices[faces[:, i]] for i in range(3))
    n = np.cross(v1 - v0, v2 - v0)
    if normalize:
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return n


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume ``sum_f v0 . (v1 x v2) / 6`` (divergence theorem), positive for outward normals.

    Parameters
    ----------
    vertices, faces : np.ndarray (N, 3), np.ndarray (M, 3) of int
        A closed mesh (km).

    Returns
    -------
    float
    """
    v0, v1, v2 = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->", v0, np.cross(v1, v2)) / 6.0)


def edge_faces(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges of a closed mesh and the two faces sharing each.

    Parameters
    ----------
    faces : np.ndarray (M, 3) of int
        Vertex indices of each face.

    Returns
    -------
    edges
        ``(E, 2)`` vertex indices ``(a, b)`` as traversed by the *first* face.
    adjacent
        ``(E, 2)`` face indices: ``adjacent[:, 0]`` traverses ``a -> b``,
        ``adjacent[:, 1]`` traverses ``b -> a``.

    Raises
    ------
    MeshError
        If the mesh is not closed and consistently wound (each directed edge must
        occur once and its reverse once).
    """
    m = faces.shape[0]
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=0)
    owner = np.tile(np.arange(m), 3)
    n = int(faces.max()) + 1
    key = directed[:, 0].astype(np.int64) * n + directed[:, 1]
    rkey = directed[:, 1].astype(np.int64) * n + directed[:, 0]
    order = np.argsort(key)
    skey = key[order]
    if np.any(skey[1:] == skey[:-1]):
        raise MeshError("mesh is not consistently wound: a directed edge is used by two faces")
    pos = np.searchsorted(skey, rkey)
    pos = np.minimum(pos, skey.size - 1)
    if not np.all(skey[pos] == rkey):
        raise MeshError("mesh is not closed: an edge has only one adjacent face")
    partner = owner[order[pos]]
    first = directed[:, 0] < directed[:, 1]
    return directed[first], np.stack([owner[first], partner[first]], axis=1)


# --------------------------------------------------------------------------- reading (readers: ._mesh_files)
def _check_face_count(n: int | None, name: str) -> None:
    from .._validate import check_memory

    if n is None:
        return
    if n > MAX_FACES:
        raise MeshError(f"{name} has {n} faces, more than the {MAX_FACES} jaxlimb reads; decimate it (a 512-px "
                        "template resolves far fewer)")
    check_memory(n * BYTES_PER_FACE, f"mesh {name} ({n} faces)", error=MeshError)


def load_mesh(path: str | os.PathLike[str], options: MeshOptions = MeshOptions()) -> Mesh:
    """Read and validate a shape model.

    Parameters
    ----------
    path
        ``.obj``, ``.stl`` (binary or ASCII), ``.ply`` (via trimesh) or a plate
        table ``.tab`` (``v``/``f`` lines, 0-based face indices).
    options
        Validation and repair options.

    Returns
    -------
    Mesh

    Raises
    ------
    MeshError
        Missing or unreadable file, unsupported format, or a mesh that fails
        validation and cannot be repaired.
    """
    from .._validate import input_file

    p = input_file(path, "mesh file", error=MeshError)
    ext = p.suffix.lower()
    if ext in TABLE_EXT or ext in TRIMESH_EXT:
        _check_face_count(declared_faces(p, ext), p.name)  # before any parsing
    if ext in TABLE_EXT:
        v, f = read_table(p)
    elif ext in TRIMESH_EXT:
        v, f = read_trimesh(p)
    else:
        raise MeshError(f"mesh file {str(p)!r}: unsupported extension {ext!r}; use .obj, .stl, .ply or .tab")
    return validate_mesh(v, f, options, source=p.name)


def validate_mesh(
    vertices: np.ndarray, faces: np.ndarray, options: MeshOptions = MeshOptions(), source: str = ""
) -> Mesh:
    """Validate (and optionally repair) a triangle mesh; see the module docstring.

    Unused vertices are kept (they never affect a silhouette).

    Parameters
    ----------
    vertices, faces : np.ndarray (N, 3), np.ndarray (M, 3) of int
        Coordinates (km, body frame) and 0-based vertex indices.
    options, source : MeshOptions, str
        Validation and repair options; the name in messages and in :attr:`Mesh.source`.

    Returns
    -------
    Mesh

    Raises
    ------
    MeshError
        A defect that cannot be repaired, or any defect with ``options.repair=False``.
    """
    name = source or "mesh"
    v, f = _checked_arrays(vertices, faces, name)
    repairs: list[str] = []
    f = _without_degenerate_faces(v, f, options, name, repairs)
    _check_closed(v.shape[0], f, name)
    try:  # consistent winding?
        edge_faces(f)
    except MeshError:
        if not options.repair:
            raise MeshError(f"{name}: faces are not consistently wound") from None
        f = _fix_winding(f)
        try:
            edge_faces(f)
        except MeshError:
            raise MeshError(f"{name}: faces are not consistently wound and could not be repaired") from None
        repairs.append("fixed inconsistent face winding")
    _check_manifold_vertices(f, name)
    vol = signed_volume(v, f)
    if not np.isfinite(vol) or vol == 0.0:
        raise MeshError(f"{name}: mesh has zero volume")
    if vol < 0:
        if not options.repair:
            raise MeshError(f"{name}: faces are wound inward (signed volume {vol:.6g} < 0)")
        f = f[:, ::-1].copy()
        repairs.append("flipped inward winding (signed volume was negative)")
    return Mesh(vertices=np.ascontiguousarray(v), faces=np.ascontiguousarray(f), repairs=tuple(repairs), source=source)


def _checked_arrays(vertices: np.ndarray, faces: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(N >= 4, 3)`` finite float64, faces ``(M >= 4, 3)`` int64 indices into them."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 4:
        raise MeshError(f"{name}: vertices must have shape (N>=4, 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise MeshError(f"{name}: {int((~np.isfinite(v)).any(axis=1).sum())} vertices are not finite")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] < 4:
        raise MeshError(f"{name}: faces must have shape (M>=4, 3), got {f.shape}")
    if not np.issubdtype(f.dtype, np.integer):
        raise MeshError(f"{name}: face indices must be integers, got dtype {f.dtype}")
    f = f.astype(np.int64)
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise MeshError(
            f"{name}: face indices must lie in [0, {v.shape[0] - 1}], got [{int(f.min())}, {int(f.max())}]"
            " (plate tables use 0-based indices)"
        )
    return v, f


def _without_degenerate_faces(v: np.ndarray, f: np.ndarray, options: MeshOptions, name: str,
                              repairs: list[str]) -> np.ndarray:
    """Faces of zero area or with a repeated vertex dropped (``options.repair``) or refused."""
    area = 0.5 * np.linalg.norm(face_normals(v, f, normalize=False), axis=1)
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    degenerate = repeated | (area <= options.degenerate_rel_area * max(float(area.mean()), 1e-300))
    if not degenerate.any():
        return f
    if not options.repair:
        raise MeshError(f"{name}: {int(degenerate.sum())} degenerate faces (zero area or repeated vertex)")
    repairs.append(f"dropped {int(degenerate.sum())} degenerate faces")
    if int((~degenerate).sum()) < 4:
        raise MeshError(f"{name}: fewer than 4 faces left after dropping degenerate faces")
    return f[~degenerate]


def _check_closed(n: int, f: np.ndarray, name: str) -> None:
    """Every edge shared by exactly two faces (a watertight surface)."""
    und = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(und[:, 0] * n + und[:, 1], return_counts=True)
    if np.any(counts != 2):
        raise MeshError(
            f"{name}: mesh is not closed (watertight): {int((counts == 1).sum())} boundary edges, "
            f"{int((counts > 2).sum())} edges shared by more than two faces; silhouettes need a closed surface"
        )


def _check_manifold_vertices(faces: np.ndarray, name: str) -> None:
    """Every vertex's faces form one fan (closed, consistently wound faces assumed): a vertex whose faces fall in two
    fans joined only at it (a "bow-tie": two bodies touching at a point) is a :class:`MeshError`.

    Around ``v`` the corner of face ``(v, a, .)`` is followed by the corner of ``v`` in the face traversing
    ``a -> v``: a permutation of the corners whose cycles are the fans, one per vertex on a manifold, labelled by
    their smallest corner (pointer doubling; no graph library: importing ``scipy.sparse`` costs a ``los locate``
    process, which verifies the mesh of its database, more than the check)."""
    corner = np.arange(3 * faces.shape[0])
    f, i = corner // 3, corner % 3
    v, a = faces[f, i], faces[f, (i + 1) % 3]  # corner ``3 f + i`` at vertex ``v``, its edge ``v -> a``
    n = int(faces.max()) + 1
    key = v.astype(np.int64) * n + a
    order = np.argsort(key)
    twin = order[np.searchsorted(key[order], a.astype(np.int64) * n + v)]  # corner of ``a`` traversing ``a -> v``
    nxt = 3 * (twin // 3) + (twin % 3 + 1) % 3  # the corner of ``v`` in that face
    label = corner.copy()
    while True:  # label = min over 2^k successors; stable labels are the cycle minima
        new = np.minimum(label, label[nxt])
        if np.array_equal(new, label):
            break
        label, nxt = new, nxt[nxt]
    roots = faces.ravel()[label == corner]  # the vertex of each fan
    if roots.size != np.unique(faces).size:
        counts = np.bincount(roots, minlength=n)
        bad = np.flatnonzero(counts > 1)
        raise MeshError(f"{name}: {bad.size} vertices (e.g. vertex {int(bad[0])}, 0-based) join separate fans of faces "
                        "(a bow-tie: parts touching at a single vertex); the surface is not a manifold")


def _fix_winding(faces: np.ndarray) -> np.ndarray:
    """Make face orientations consistent by breadth-first propagation over shared edges.

    Two faces sharing an edge are consistent when they traverse it in opposite
    directions; the first face of each connected component keeps its orientation
    (the global sign is fixed afterwards with the signed volume).
    """
    from collections import deque

    f = faces.copy()
    m = f.shape[0]
    n = int(f.max()) + 1
    und = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    key = und[:, 0] * n + und[:, 1]
    owner = np.tile(np.arange(m), 3)
    order = np.argsort(key, kind="stable")
    ks, os_ = key[order], owner[order]
    neighbours: list[list[int]] = [[] for _ in range(m)]
    for i in range(0, ks.size - 1):
        if ks[i] == ks[i + 1]:
            a, b = int(os_[i]), int(os_[i + 1])
            neighbours[a].append(b)
            neighbours[b].append(a)
    done = np.zeros(m, dtype=bool)

    def directed(face: np.ndarray) -> set[tuple[int, int]]:
        return {(int(face[0]), int(face[1])), (int(face[1]), int(face[2])), (int(face[2]), int(face[0]))}

    for seed in range(m):
        if done[seed]:
            continue
        done[seed] = True
        queue = deque([seed])
        while queue:
            a = queue.popleft()
            da = directed(f[a])
            for b in neighbours[a]:
                if done[b]:
                    continue
                if da & directed(f[b]):  # same direction on the shared edge: flip b
                    f[b] = f[b, ::-1]
                done[b] = True
                queue.append(b)
    return f


def mesh_hash(mesh: Mesh) -> str:
    """SHA-256 of the validated vertex (float64) and face (int64) arrays, hex.

    Parameters
    ----------
    mesh : Mesh

    Returns
    -------
    str
    """
    h = hashlib.sha256()
    h.update(b"jaxlimb-mesh-v1")
    h.update(np.ascontiguousarray(mesh.vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype="<i8").tobytes())
    return h.hexdigest()


__all__ = [
    "BYTES_PER_FACE", "MAX_FACES", "Mesh", "MeshOptions", "edge_faces", "face_normals", "load_mesh", "mesh_hash",
    "signed_volume", "validate_mesh",
]  # fmt: skip
