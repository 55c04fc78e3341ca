"""``jaxlimb los build-db`` / ``jaxlimb los locate`` and the error contract."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import trimesh
from irregular_helpers import render_view

import jaxlimb.cli as cli
from jaxlimb.irregular.views import view_count


@pytest.fixture(autouse=True)
def only_los(monkeypatch, tmp_path):
    """Run the CLI with only this sub-command registered (others may not be in the tree yet)."""
    monkeypatch.setattr(cli, "_COMMANDS", ("_los",))
    monkeypatch.setenv("JAXLIMB_CACHE", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from irregular_helpers import lumpy_ellipsoid

    from jaxlimb.geometry.camera import Camera

    d = tmp_path_factory.mktemp("scene")
    mesh = lumpy_ellipsoid(subdivisions=3)
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    mesh_path = d / "lumpy.obj"
    tm.export(mesh_path)
    cam = Camera(rows=300, cols=400)
    (d / "camera.json").write_text(json.dumps(cam.to_dict()))
    out = render_view(mesh, cam, [0.3, -0.5, 0.8], 150.0, roll=0.4, offset_px=(5.0, -12.0), quantize_bits=8)
    cv2.imwrite(str(d / "img.png"), out.image.astype(np.uint8))
    return d, out.center_rc


def _run(capsys, argv):
    code = cli.main(argv)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_build_then_locate_json(scene, capsys, tmp_path, monkeypatch):
    d, truth = scene
    monkeypatch.setenv("JAXLIMB_PROGRESS", "1")  # bars on, as on a terminal: the build's bar is checked
    db = tmp_path / "db.npz"
    code, out, err = _run(capsys, ["los", "build-db", str(d / "lumpy.obj"), "--step-deg", "10", "--template-size", "256", "--out", str(db), "--json"])
    assert code == 0, out + err
    summary = json.loads(out)
    assert summary["n_templates"] == view_count(10.0) and db.is_file()
    assert "templates" in err  # progress bar on stderr
    code, out, err = _run(capsys, ["los", "locate", str(d / "img.png"), "--db", str(db), "--camera", str(d / "camera.json"), "--json", "--no-refine"])
    assert code == 0, out + err
    res = json.loads(out)
    assert res["status"] == "ok"
    assert set(res) >= {"center_rc", "los_camera", "template", "match_distance"}
    assert np.linalg.norm(np.array(res["center_rc"]) - truth) < 2.0  # coarse 10-degree database
    assert abs(np.linalg.norm(res["los_camera"]) - 1) < 1e-12
    assert set(res["template"]) >= {"index", "alpha_deg", "beta_deg", "rotation_deg", "scale"}


def test_locate_with_mesh_builds_cache_once(scene, capsys, tmp_path, monkeypatch):
    """The database is built once; later calls find it by the mesh file's content without reading the mesh, and
    a record whose database is gone falls back to reading the mesh (and building again)."""
    import jaxlimb.irregular.mesh as mesh_module

    monkeypatch.setenv("JAXLIMB_PROGRESS", "1")  # bars on, as on a terminal: the bar witnesses a build
    d, _ = scene
    argv = ["los", "locate", str(d / "img.png"), "--mesh", str(d / "lumpy.obj"), "--camera", str(d / "camera.json"), "--step-deg", "30", "--template-size", "128", "--json", "--no-refine"]
    code, out, err = _run(capsys, argv)
    assert code == 0, out + err
    assert "templates" in err
    cached = list((tmp_path / "cache").glob("*.npz"))
    assert len(cached) == 1 and len(list((tmp_path / "cache").glob("los-mesh-file-*.json"))) == 1
    load_mesh = mesh_module.load_mesh
    monkeypatch.setattr(mesh_module, "load_mesh", lambda *a, **k: pytest.fail("the mesh was read again"))
    code, out2, err2 = _run(capsys, argv)
    assert code == 0 and "templates" not in err2, err2  # no rebuild, no mesh read
    assert json.loads(out2)["center_rc"] == json.loads(out)["center_rc"]
    monkeypatch.setattr(mesh_module, "load_mesh", load_mesh)
    cached[0].unlink()
    code, out3, err3 = _run(capsys, argv)
    assert code == 0 and "templates" in err3  # rebuilt from the mesh
    assert json.loads(out3)["center_rc"] == json.loads(out)["center_rc"]


@pytest.mark.parametrize(
    "mutate, code, check",
    [
        (lambda d: ["--db", str(d / "missing.npz")], 2, "bad_database"),
        (lambda d: ["--db", str(d / "camera.json")], 2, "bad_database"),
        (lambda d: ["--mesh", str(d / "camera.json")], 2, "bad_mesh"),
    ],
)
def test_errors_json(scene, capsys, mutate, code, check):
    d, _ = scene
    argv = ["los", "locate", str(d / "img.png"), *mutate(d), "--camera", str(d / "camera.json"), "--json"]
    rc, out, err = _run(capsys, argv)
    assert rc == code
    obj = json.loads(out)
    assert obj["status"] == "error" and obj["check"] == check
    assert "Traceback" not in out + err


def test_bad_image_and_camera(scene, capsys, tmp_path):
    d, _ = scene
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\nbroken")
    db = tmp_path / "db.npz"
    assert cli.main(["los", "build-db", str(d / "lumpy.obj"), "--step-deg", "30", "--template-size", "128", "--out", str(db), "--no-progress"]) == 0
    capsys.readouterr()
    rc, out, _ = _run(capsys, ["los", "locate", str(tmp_path / "broken.png"), "--db", str(db), "--camera", str(d / "camera.json"), "--json"])
    assert rc == 2 and json.loads(out)["check"] == "bad_image"
    rc, out, _ = _run(capsys, ["los", "locate", str(tmp_path / "nope.png"), "--db", str(db), "--camera", str(d / "camera.json"), "--json"])
    assert rc == 2 and json.loads(out)["status"] == "error"
    (tmp_path / "cam.json").write_text("{not json")
    rc, out, _ = _run(capsys, ["los", "locate", str(d / "img.png"), "--db", str(db), "--camera", str(tmp_path / "cam.json"), "--json"])
    assert rc == 2 and json.loads(out)["check"] == "bad_config"
    # a failed check: an all-black image -> exit 3
    cv2.imwrite(str(tmp_path / "black.png"), np.zeros((300, 400), np.uint8))
    rc, out, _ = _run(capsys, ["los", "locate", str(tmp_path / "black.png"), "--db", str(db), "--camera", str(d / "camera.json"), "--json"])
    assert rc in (2, 3) and json.loads(out)["status"] == "error"
    # a body cut by the border -> exit 3 (check failed), not a traceback
    img = np.zeros((300, 400), np.uint8)
    img[0:60, 100:200] = 200
    cv2.imwrite(str(tmp_path / "cut.png"), img)
    rc, out, _ = _run(capsys, ["los", "locate", str(tmp_path / "cut.png"), "--db", str(db), "--camera", str(d / "camera.json"), "--json"])
    assert rc == 3 and json.loads(out)["check"] == "too_big"
    # without --json: one line on stderr
    rc, out, err = _run(capsys, ["los", "locate", str(tmp_path / "cut.png"), "--db", str(db), "--camera", str(d / "camera.json")])
    assert rc == 3 and out == "" and len(err.strip().splitlines()) == 1


def test_missing_arguments_exit_2(capsys):
    rc, out, _ = _run(capsys, ["los", "locate", "x.png", "--json"])
    assert rc == 2 and json.loads(out)["check"] == "bad_arguments"


def test_locate_many_frames_loads_the_database_once(scene, capsys, tmp_path):
    """Many frames: one JSON line per frame; a wrong-size frame is an error line, the run goes on."""
    d, truth = scene
    db = tmp_path / "db.npz"
    assert cli.main(["los", "build-db", str(d / "lumpy.obj"), "--step-deg", "30", "--template-size", "128", "--out", str(db), "--no-progress"]) == 0
    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((30, 40), np.uint8))
    out = tmp_path / "los.jsonl"
    argv = ["los", "locate", str(d / "img.png"), str(tmp_path / "small.png"), "--db", str(db), "--camera", str(d / "camera.json"),
            "--no-refine", "--out", str(out)]
    rc, _, err = _run(capsys, argv)
    assert rc == 2 and "Traceback" not in err
    recs = [json.loads(s) for s in out.read_text().splitlines()]
    assert [r["status"] for r in recs] == ["ok", "error"] and recs[1]["image"].endswith("small.png")
    assert np.linalg.norm(np.array(recs[0]["center_rc"]) - truth) < 3.0
    rc, _, err = _run(capsys, [*argv, "--resume"])
    assert rc == 0 and "0 frames" in err  # both frames answered: nothing to do


def test_locate_checked_modes_and_wrong_body(scene, capsys, tmp_path):
    """Attitude known -> render-and-register; another body's frame -> a typed failure (exit 3)."""
    from irregular_helpers import lumpy_ellipsoid

    from jaxlimb.geometry.camera import Camera
    from jaxlimb.irregular.shapes import ShapeFamily, generate_shape
    from jaxlimb.render.mesh import MeshRenderOptions, look_at_rotation, render_mesh

    d, _ = scene
    mesh = lumpy_ellipsoid(subdivisions=3)
    cam = Camera.from_json(d / "camera.json")
    R = look_at_rotation(np.array([0.2, 0.7, 0.5]), roll_rad=1.1)
    t = np.array([0.4, -0.3, 2.0 * mesh.max_radius * cam.focal_px / 140.0])
    sun = -t / np.linalg.norm(t) * np.cos(0.7) + np.array([1.0, 0.0, 0.0]) * np.sin(0.7)
    sun /= np.linalg.norm(sun)
    out = render_mesh(mesh.vertices, mesh.faces, cam, R, t, sun, MeshRenderOptions(albedo=100.0, noise_sigma=1.0, quantize_bits=8))
    cv2.imwrite(str(tmp_path / "lit.png"), out.image.astype(np.uint8))
    (tmp_path / "hints.json").write_text(json.dumps({"sun_dir_camera": sun.tolist(), "R_body_to_camera": R.tolist()}))
    db = tmp_path / "db.npz"
    assert cli.main(["los", "build-db", str(d / "lumpy.obj"), "--step-deg", "30", "--template-size", "128", "--out", str(db), "--no-progress"]) == 0
    capsys.readouterr()
    base = ["--db", str(db), "--camera", str(d / "camera.json"), "--json"]
    rc, o, err = _run(capsys, ["los", "locate", str(tmp_path / "lit.png"), *base, "--hints", str(tmp_path / "hints.json")])
    assert rc == 0, o + err
    res = json.loads(o)
    assert res["mode"] == "known-attitude" and res["checked"] is True
    assert np.linalg.norm(np.array(res["center_rc"]) - out.center_rc) < 0.05  # 8-bit quantised frame, not saturated
    assert np.all(np.linalg.eigvalsh(np.array(res["covariance"]["center_rc"])) > 0)
    # a frame of another body against this body's model: exit 3, never ok
    other = generate_shape(ShapeFamily.CONTACT_BINARY, 3)
    t2 = np.array([0.0, 0.0, 2.0 * other.max_radius * cam.focal_px / 140.0])
    img2 = render_mesh(other.vertices, other.faces, cam, R, t2, sun, MeshRenderOptions(albedo=100.0, noise_sigma=1.0, quantize_bits=8)).image
    cv2.imwrite(str(tmp_path / "other.png"), img2.astype(np.uint8))
    for extra in ([], ["--hints", str(tmp_path / "hints.json")]):
        rc, o, err = _run(capsys, ["los", "locate", str(tmp_path / "other.png"), *base, *extra])
        assert rc == 3, o + err
        assert json.loads(o)["check"] in ("poor_match", "ambiguous_match", "no_convergence")


def test_locate_process_never_starts_jax(scene, capsys, tmp_path):
    """``los locate`` is numpy + OpenCV only (<= 3 s per call): a whole checked call in a fresh
    process imports neither JAX nor the limb pipeline (which pulls JAX in: 0.8 s of a 3 s call), nor
    ``scipy.sparse`` (the database's mesh is verified without a graph library: its import costs more than the check)."""
    import os
    import subprocess
    import sys

    d, truth = scene
    db = tmp_path / "db.npz"
    assert cli.main(["los", "build-db", str(d / "lumpy.obj"), "--step-deg", "30", "--template-size", "128", "--out", str(db), "--no-progress"]) == 0
    capsys.readouterr()
    argv = ["los", "locate", str(d / "img.png"), "--db", str(db), "--camera", str(d / "camera.json"), "--json"]
    code = ("import contextlib, io, json, sys\nfrom jaxlimb.cli import main\n"
            f"with contextlib.redirect_stdout(io.StringIO()) as out:\n    rc = main({argv!r})\n"
            "print(json.dumps([rc, out.getvalue(), sorted(m for m in sys.modules if m in ('jax', 'scipy.sparse') or m.startswith(('jax.', 'jaxlimb.pipeline')))]))")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                       env={**os.environ, "JAXLIMB_CACHE": str(tmp_path / "cache")})
    rc, out, jax_modules = json.loads(p.stdout.strip().splitlines()[-1])
    assert rc == 0, out + p.stderr
    assert np.linalg.norm(np.array(json.loads(out)["center_rc"]) - truth) < 0.5
    assert jax_modules == []
