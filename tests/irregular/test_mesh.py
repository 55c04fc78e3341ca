"""Mesh reading, validation and repair."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from jaxlimb.errors import MeshError
from jaxlimb.irregular.mesh import MeshOptions, edge_faces, load_mesh, mesh_hash, signed_volume, validate_mesh

from irregular_helpers import EROS, THEBE


def _box():
    b = trimesh.creation.box(extents=(2.0, 3.0, 4.0))
    return np.asarray(b.vertices, float), np.asarray(b.faces)


def test_real_meshes_load_closed_and_outward():
    for path, nv, nf in ((THEBE, 2522, 5040), (EROS, 3897, 7790)):
        m = load_mesh(path)
        assert (m.n_vertices, m.n_faces) == (nv, nf)
        assert m.volume > 0  # outward normals, verified not assumed
        assert m.repairs == ()
        edges, adj = edge_faces(m.faces)
        assert edges.shape[0] == 3 * nf // 2  # closed: every edge shared by exactly two faces


def test_eros_table_is_zero_based():
    m = load_mesh(EROS)
    assert m.faces.min() == 0 and m.faces.max() == m.n_vertices - 1


@pytest.mark.parametrize("fmt", ["stl", "stl_ascii", "ply", "obj"])
def test_trimesh_formats_roundtrip(tmp_path, fmt):
    v, f = _box()
    tm = trimesh.Trimesh(v, f, process=False)
    ext = "stl" if fmt.startswith("stl") else fmt
    p = tmp_path / f"box.{ext}"
    if fmt == "stl_ascii":
        p.write_text(trimesh.exchange.stl.export_stl_ascii(tm))
    else:
        tm.export(p)
    m = load_mesh(p)
    assert m.n_faces == 12
    assert m.volume == pytest.approx(24.0, rel=1e-9)
    assert m.repairs == ()


def test_table_reader(tmp_path):
    v, f = _box()
    lines = [f"v {a:.9f} {b:.9f} {c:.9f}" for a, b, c in v] + [f"f {i} {j} {k}" for i, j, k in f]
    p = tmp_path / "box.tab"
    p.write_text("\n".join(lines) + "\n")
    m = load_mesh(p)
    assert m.volume == pytest.approx(24.0, rel=1e-9)


def test_table_one_based_indices_refused(tmp_path):
    v, f = _box()
    lines = [f"v {a} {b} {c}" for a, b, c in v] + [f"f {i + 1} {j + 1} {k + 1}" for i, j, k in f]
    p = tmp_path / "box.tab"
    p.write_text("\n".join(lines))
    with pytest.raises(MeshError, match="0-based"):
        load_mesh(p)


def test_inverted_mesh_is_flipped_or_refused():
    v, f = _box()
    inv = f[:, ::-1]
    assert signed_volume(v, inv) < 0
    m = validate_mesh(v, inv)
    assert m.volume == pytest.approx(24.0)
    assert any("flipped" in r for r in m.repairs)
    with pytest.raises(MeshError, match="inward"):
        validate_mesh(v, inv, MeshOptions(repair=False))


def test_inconsistent_winding_repaired_or_refused():
    v, f = _box()
    g = f.copy()
    g[3] = g[3, ::-1]
    m = validate_mesh(v, g)
    assert m.volume == pytest.approx(24.0)
    assert any("winding" in r for r in m.repairs)
    with pytest.raises(MeshError, match="consistently wound"):
        validate_mesh(v, g, MeshOptions(repair=False))


def test_degenerate_faces_dropped_or_refused():
    v, f = _box()
    g = np.vstack([f, [[0, 0, 1]]])
    m = validate_mesh(v, g)
    assert m.n_faces == 12 and any("degenerate" in r for r in m.repairs)
    with pytest.raises(MeshError, match="degenerate"):
        validate_mesh(v, g, MeshOptions(repair=False))


def test_open_mesh_refused():
    v, f = _box()
    with pytest.raises(MeshError, match="not closed"):
        validate_mesh(v, f[:-1])


@pytest.mark.parametrize(
    "content, match",
    [("", "has 0 vertices"), ("v 1 2\n", "unrecognised line"), ("v a b c\n", "not a")],
)
def test_bad_table_files(tmp_path, content, match):
    p = tmp_path / "bad.tab"
    p.write_text(content)
    with pytest.raises(MeshError, match=match):
        load_mesh(p)


def test_missing_and_unsupported(tmp_path):
    with pytest.raises(MeshError, match="does not exist"):
        load_mesh(tmp_path / "nope.obj")
    p = tmp_path / "x.xyz"
    p.write_text("1 2 3")
    with pytest.raises(MeshError, match="unsupported extension"):
        load_mesh(p)
    q = tmp_path / "garbage.stl"
    q.write_bytes(b"\x00\x01garbage")
    with pytest.raises(MeshError):
        load_mesh(q)


def test_nonfinite_vertices_refused():
    v, f = _box()
    v[0, 0] = np.nan
    with pytest.raises(MeshError, match="not finite"):
        validate_mesh(v, f)


def test_hash_depends_on_content():
    v, f = _box()
    a = validate_mesh(v, f)
    b = validate_mesh(v + 1e-9, f)
    assert mesh_hash(a) == mesh_hash(validate_mesh(v.copy(), f.copy()))
    assert mesh_hash(a) != mesh_hash(b)


# --------------------------------------------------------------------------- manifold, index base, size bound
def _two_tetrahedra_touching_at_a_vertex() -> tuple[np.ndarray, np.ndarray]:
    """A bow-tie: two closed, outward tetrahedra that share vertex 0 and nothing else."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], float)
    t1 = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    t2 = np.array([[0, 4, 5], [0, 6, 4], [0, 5, 6], [4, 6, 5]])
    return v, np.concatenate([t1, t2])


def test_bow_tie_vertex_is_refused_with_or_without_repair():
    v, f = _two_tetrahedra_touching_at_a_vertex()
    for repair in (True, False):
        with pytest.raises(MeshError, match="vertex 0.*bow-tie"):
            validate_mesh(v, f, MeshOptions(repair=repair))


def _bipyramid(n: int, apex: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A closed, outward bipyramid over an ``n``-gon: its two apices have valence ``n``."""
    ang = 2 * np.pi * np.arange(n) / n
    v = np.concatenate([[[0, 0, 1], [0, 0, -1]], np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], axis=1)])
    ring = 2 + np.arange(n)
    nxt = 2 + (np.arange(n) + 1) % n
    f = np.concatenate([np.stack([np.zeros(n, int), ring, nxt], axis=1), np.stack([np.ones(n, int), nxt, ring], axis=1)])
    return v, f


def test_long_fans_are_one_fan_and_three_fans_at_a_vertex_are_refused():
    """Fans of 64 faces (the apices) are one fan each; three bipyramids sharing an apex are a bow-tie there."""
    v, f = _bipyramid(64)
    assert validate_mesh(v, f, MeshOptions(repair=False)).n_faces == 128
    vs, fs = [v], [f]
    for k in (1, 2):  # two more bipyramids whose top apex is vertex 0 of the first
        vk, fk = _bipyramid(64)
        fk = np.where(fk == 0, 0, fk + len(np.concatenate(vs)) - 1)
        vs.append(vk[1:] + [3.0 * k, 0.0, 0.0])
        fs.append(fk)
    with pytest.raises(MeshError, match="1 vertices \\(e.g. vertex 0, 0-based\\).*bow-tie"):
        validate_mesh(np.concatenate(vs), np.concatenate(fs), MeshOptions(repair=False))


def test_obj_index_zero_is_refused_before_trimesh_reads_it_as_the_last_vertex(tmp_path):
    verts, faces = _box()
    lines = [f"v {x} {y} {z}" for x, y, z in verts] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    p = tmp_path / "box.obj"
    p.write_text("\n".join(lines) + "\n")
    assert load_mesh(p).n_faces == len(faces)
    lines[-1] = lines[-1].rsplit(" ", 1)[0] + " 0"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeshError, match=f"line {len(lines)} uses the vertex index 0"):
        load_mesh(p)


def test_face_count_is_bounded_from_the_header_before_parsing(tmp_path, monkeypatch):
    import jaxlimb.irregular.mesh as mesh_mod
    from jaxlimb.irregular._mesh_files import declared_faces

    box = trimesh.Trimesh(*_box(), process=False)
    for fmt in ("stl", "ply", "obj", "off"):
        p = tmp_path / f"box.{fmt}"
        box.export(p)
        assert declared_faces(p, f".{fmt}") == len(box.faces)
    monkeypatch.setattr(mesh_mod, "MAX_FACES", len(box.faces) - 1)
    with pytest.raises(MeshError, match=f"{len(box.faces)} faces, more than"):
        load_mesh(tmp_path / "box.stl")
