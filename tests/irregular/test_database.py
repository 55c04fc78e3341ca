"""Template database: content, atomic versioned file, refusal of bad files."""

from __future__ import annotations

import dataclasses
import zipfile

import numpy as np
import pytest

from jaxlimb import _jaxcache as jaxcache
from jaxlimb.errors import CacheRepairWarning, DatabaseError
from jaxlimb.irregular import database as dbm
from jaxlimb.irregular.database import (
    DatabaseOptions,
    build_database,
    cache_path,
    cached_database,
    load_database,
    save_database,
)
from jaxlimb.irregular.mesh import mesh_hash, validate_mesh
from jaxlimb.irregular.views import view_count


def test_content(lumpy_db, lumpy):
    db = lumpy_db
    assert len(db) == view_count(10.0)
    assert db.mesh_hash == mesh_hash(lumpy)
    assert np.all(db.area > 0)
    # P_B is the principal point; the lumpy mesh's origin is off its centroid so C_B != P_B
    off = np.linalg.norm(db.center_rc - db.center_image_rc, axis=1)
    assert off.max() > 1.0
    assert np.all(np.isfinite(db.hu))
    # antipodal views give mirror-image figures: opposite sign of h7 (exactly so in the orthographic limit)
    n = len(db)
    assert np.allclose(db.hu[0, :2], db.hu[n - 1, :2], rtol=0.05)  # perspective (20 radii) perturbs h3..h6 more
    assert np.sign(db.hu[0, 6]) == -np.sign(db.hu[n - 1, 6])


def test_roundtrip(tmp_path, lumpy_db):
    p = save_database(lumpy_db, tmp_path / "db.npz")
    db2 = load_database(p, expected_mesh_hash=lumpy_db.mesh_hash, expected_options=lumpy_db.options)
    for k in ("alpha", "area", "center_rc", "hu", "contour_xy", "R_body_to_camera"):
        assert np.array_equal(getattr(db2, k), getattr(lumpy_db, k))
    assert db2.options == lumpy_db.options
    assert np.array_equal(db2.mesh.vertices, lumpy_db.mesh.vertices)
    assert not list(tmp_path.glob(".*tmp"))  # no temporary left behind


def test_truncated_and_corrupt_refused(tmp_path, lumpy_db):
    p = save_database(lumpy_db, tmp_path / "db.npz")
    data = p.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(DatabaseError, match="corrupt|truncated|cannot be read"):
        load_database(tmp_path / "trunc.npz")
    flipped = bytearray(data)
    i = len(flipped) // 3
    flipped[i] ^= 0xFF
    (tmp_path / "flip.npz").write_bytes(bytes(flipped))
    with pytest.raises(DatabaseError):
        load_database(tmp_path / "flip.npz")
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(DatabaseError):
        load_database(tmp_path / "empty.npz")
    with pytest.raises(DatabaseError, match="does not exist"):
        load_database(tmp_path / "missing.npz")


def _rewrite(src, dst, **changes):
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    arrays.update(changes)
    if "checksum" not in changes:
        arrays["checksum"] = np.array(dbm._checksum(arrays))
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)


def test_other_version_settings_mesh_refused(tmp_path, lumpy_db):
    p = save_database(lumpy_db, tmp_path / "db.npz")
    _rewrite(p, tmp_path / "v99.npz", format_version=np.array(99))
    with pytest.raises(DatabaseError, match="version 99"):
        load_database(tmp_path / "v99.npz")
    _rewrite(p, tmp_path / "badsum.npz", checksum=np.array("0" * 64))
    with pytest.raises(DatabaseError, match="checksum"):
        load_database(tmp_path / "badsum.npz")
    _rewrite(p, tmp_path / "badhash.npz", mesh_hash=np.array("f" * 64))
    with pytest.raises(DatabaseError, match="does not match its hash"):
        load_database(tmp_path / "badhash.npz")
    _rewrite(p, tmp_path / "shape.npz", hu=np.zeros((3, 7)))
    with pytest.raises(DatabaseError, match="shape"):
        load_database(tmp_path / "shape.npz")
    with pytest.raises(DatabaseError, match="built for mesh"):
        load_database(p, expected_mesh_hash="a" * 64)
    other = dataclasses.replace(lumpy_db.options, step_deg=15.0)
    with pytest.raises(DatabaseError, match="settings"):
        load_database(p, expected_options=other)
    (tmp_path / "notdb.npz").write_bytes(b"PK\x03\x04 not a zip really")
    with pytest.raises(DatabaseError):
        load_database(tmp_path / "notdb.npz")
    with zipfile.ZipFile(tmp_path / "foreign.npz", "w") as z:
        z.writestr("x.npy", b"")
    with pytest.raises(DatabaseError):
        load_database(tmp_path / "foreign.npz")


def test_version_1_file_still_reads(tmp_path, lumpy_db):
    """Version 1 spelled the template centres ``centre_rc``; such a file loads with the same values."""
    p = save_database(lumpy_db, tmp_path / "db.npz")
    with np.load(p) as z:
        arrays = {("centre_rc" if k == "center_rc" else k): z[k] for k in z.files}
    arrays["format_version"] = np.array(1)
    arrays["checksum"] = np.array(dbm._checksum(arrays))
    with open(tmp_path / "v1.npz", "wb") as fh:
        np.savez(fh, **arrays)
    db1 = load_database(tmp_path / "v1.npz", expected_mesh_hash=lumpy_db.mesh_hash)
    assert np.array_equal(db1.center_rc, lumpy_db.center_rc)
    arrays["format_version"] = np.array(2)  # the old name under the new version is not accepted
    arrays["checksum"] = np.array(dbm._checksum(arrays))
    with open(tmp_path / "v2old.npz", "wb") as fh:
        np.savez(fh, **arrays)
    with pytest.raises(DatabaseError, match="lacks arrays"):
        load_database(tmp_path / "v2old.npz")


def test_failed_write_leaves_old_file(tmp_path, lumpy_db, monkeypatch):
    p = save_database(lumpy_db, tmp_path / "db.npz")
    before = p.read_bytes()

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(OSError):
        save_database(lumpy_db, p)
    assert p.read_bytes() == before
    assert not list(tmp_path.glob(".*tmp"))


def test_cache_builds_once(tmp_path, monkeypatch, lumpy):
    monkeypatch.setenv("JAXLIMB_CACHE", str(tmp_path / "cache"))
    opts = DatabaseOptions(step_deg=30.0, template_size_px=128)
    calls = []
    real = dbm.build_database

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(dbm, "build_database", counting)
    a = cached_database(lumpy, opts, progress=False)
    b = cached_database(lumpy, opts, progress=False)
    assert len(calls) == 1 and len(a) == len(b) == view_count(30.0)
    p = cache_path(lumpy, opts)
    assert p.parent == tmp_path / "cache" and p.is_file()
    # another mesh or other settings -> another file
    other = validate_mesh(lumpy.vertices * 1.01, lumpy.faces)
    assert cache_path(other, opts) != p
    assert cache_path(lumpy, dataclasses.replace(opts, step_deg=20.0)) != p
    # a corrupt cache file is rebuilt, not half-read, and a warning says so
    p.write_bytes(b"garbage")
    monkeypatch.setattr(jaxcache, "_WARNED", set())  # said once per process: this test's own process state
    with pytest.warns(CacheRepairWarning, match="rebuilt"):
        c = cached_database(lumpy, opts, progress=False)
    assert len(calls) == 2 and len(c) == len(a)


def test_progress_bar(capsys, lumpy):
    build_database(lumpy, DatabaseOptions(step_deg=30.0, template_size_px=64), progress=True)
    assert "templates" in capsys.readouterr().err
