"""The mesh-file readers of :func:`~jaxlimb.irregular.mesh.load_mesh`: trimesh's formats and the PDS-style plate tables.

:func:`declared_faces` reads the face count a file declares without parsing it (checked against
:data:`~jaxlimb.irregular.mesh.MAX_FACES` first); the readers return the raw ``(vertices, faces)`` arrays, which
:func:`~jaxlimb.irregular.mesh.validate_mesh` then checks.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import MeshError

TRIMESH_EXT = {".obj", ".stl", ".ply", ".off", ".glb", ".gltf"}
TABLE_EXT = {".tab", ".txt", ".dat"}


def read_table(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a PDS-style plate table: ``v x y z`` and ``f i j k`` lines, 0-based faces."""
    verts: list[list[float]] = []
    faces: list[list[int]] = []
    try:
        with open(path, encoding="ascii", errors="strict") as fh:
            for lineno, line in enumerate(fh, 1):
                parts = line.split()
                if not parts or parts[0].startswith("#"):
                    continue
                tag = parts[0].lower()
                if tag == "v" and len(parts) >= 4:
                    verts.append([float(p) for p in parts[1:4]])
                elif tag == "f" and len(parts) >= 4:
                    faces.append([int(p) for p in parts[1:4]])
                else:
                    raise MeshError(f"mesh table {str(path)!r}: unrecognised line {lineno}: {line.strip()[:60]!r}")
    except (UnicodeDecodeError, ValueError) as e:
        raise MeshError(f"mesh table {str(path)!r} is not a `v x y z` / `f i j k` table: {e}") from None
    if not verts or not faces:
        raise MeshError(f"mesh table {str(path)!r} has {len(verts)} vertices and {len(faces)} faces; need both")
    return np.asarray(verts, dtype=np.float64), np.asarray(faces, dtype=np.int64)


#: Formats that are text only: a file that is not UTF-8 text is not a mesh of that format.
_TEXT_EXT = {".obj", ".off", ".gltf"}


def _check_text(path: Path) -> None:
    """A text-only format (OBJ ...) that is binary garbage is "not a mesh" (trimesh would try to
    guess its encoding and fail with an unrelated error)."""
    head = path.read_bytes()[: 1 << 16]
    try:
        ok = b"\0" not in head and head.decode("utf-8", errors="strict") is not None
    except UnicodeDecodeError as e:
        ok = e.start > len(head) - 4  # a multi-byte character cut by the 64 KiB window
    if not ok:
        raise MeshError(f"{str(path)!r} is not a mesh: a {path.suffix} file must be text, this one is binary")


def read_trimesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    if path.suffix.lower() in _TEXT_EXT:
        _check_text(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tm = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many types on bad files
        raise MeshError(f"{str(path)!r} is not a readable mesh: {type(e).__name__}: {e}") from None
    if not isinstance(tm, trimesh.Trimesh) or len(tm.faces) == 0:
        raise MeshError(f"{str(path)!r} is not a mesh: it holds no triangles")
    bad = ~np.isfinite(np.asarray(tm.vertices, dtype=np.float64)).all(axis=1)
    if bad.any():  # trimesh's processing would drop them silently and leave a hole
        raise MeshError(f"{path.name}: {int(bad.sum())} vertices are not finite (NaN/inf), e.g. vertex {int(np.argmax(bad)) + 1}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tm.process()  # merges duplicate vertices (STL stores each triangle on its own)
    return np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64)


_OBJ_ZERO_INDEX = re.compile(rb"(?m)^f[ \t][^\n]*?[ \t]0(?:/|[ \t]|\r?$)")
_PLY_FACES = re.compile(rb"(?m)^element\s+face\s+(\d+)")


def declared_faces(path: Path, ext: str) -> int | None:
    """Faces a mesh file declares, from its header or its ``f`` lines, without parsing it; ``None`` if unknown.

    Raises :class:`~jaxlimb.errors.MeshError` for an OBJ face with the index 0 (OBJ counts from 1).
    """
    size = path.stat().st_size
    if ext == ".stl":
        with open(path, "rb") as fh:
            head = fh.read(84)
        n = int.from_bytes(head[80:84], "little") if len(head) == 84 else 0
        if size == 84 + 50 * n:
            return n
        return path.read_bytes().count(b"facet normal")
    if ext == ".ply":
        m = _PLY_FACES.search(path.read_bytes()[:65536])
        return int(m.group(1)) if m else None
    if ext in (".obj", *TABLE_EXT):
        data = path.read_bytes()
        if ext == ".obj":
            bad = _OBJ_ZERO_INDEX.search(data)
            if bad:
                line = data.count(b"\n", 0, bad.start()) + 1
                raise MeshError(f"{path.name}: face on line {line} uses the vertex index 0; OBJ indices start at 1")
        return data.count(b"\nf ") + data.count(b"\nf\t") + data.startswith((b"f ", b"f\t"))
    if ext == ".off":
        words = [w for ln in path.read_bytes()[:4096].splitlines() if not ln.strip().startswith(b"#")
                 for w in ln.split()]
        return int(words[2]) if len(words) > 2 and words[2].isdigit() else None
    return None
