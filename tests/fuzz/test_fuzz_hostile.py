"""Files that are not what they claim, and flags whose stated bounds must be the enforced ones.

JSON with a key twice, absurd nesting or a 5000-digit integer (a byte-order mark is fine); a text file or a
PNG given as a SPICE kernel; OBJ meshes with the index 0, a bow-tie vertex, or more faces than jaxlimb
reads; ``--resume`` of a file written by another command, camera or options, or holding garbage; a FIFO
or a device as ``--out``; bounds stated by ``--help`` (``montecarlo --annulus``).  Each is exit 2 with one
line naming what is wrong -- never exit 1, never an answer.
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import pytest

from ._cli import assert_refused, run_cli

CASSINI = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "cassini"


# ----------------------------------------------------------------------------- JSON
@pytest.mark.parametrize(("role", "text", "names"), [
    ("hints", '{"body": "moon", "range_prior_km": 30000, "body": "earth"}', "'body' twice"),
    ("camera", '{"rows": 120, "rows": 120}', "'rows' twice"),
    ("camera", "[" * 200_000 + "]" * 200_000, "200000 deep"),
    ("hints", '{"range_prior_km": ' + "7" * 5000 + "}", "5000 digits"),
])
def test_json_that_is_not_what_it_claims_exits_2(role, text, names, inputs, tmp_path):
    bad = tmp_path / f"{role}.json"
    bad.write_text(text)
    files = {"camera": inputs["camera.json"], "hints": inputs["hints.json"], role: bad}
    res = run_cli(["locate", inputs["moon.png"], "--camera", files["camera"], "--hints", files["hints"], "--json"])
    assert_refused(res, 2, names, check="bad_config")


def test_attitude_json_is_read_strictly(inputs, tmp_path):
    text = '{"quaternion": [0, 0, 0, 1], "quaternion": [1, 0, 0, 0]}'
    bad = tmp_path / "att.json"
    bad.write_text(text)
    for attitude in (bad, text):  # a file, or the JSON itself on the command line
        res = run_cli(["navigate", inputs["moon.png"], "--camera", inputs["camera.json"], "--epoch",
                       "2026-01-01T00:00:00Z", "--attitude", attitude, "--json"])
        assert_refused(res, 2, "'quaternion' twice", check="bad_config")


# ----------------------------------------------------------------------------- SPICE kernels
@pytest.mark.parametrize("which", ["text.txt", "moon.png"])
def test_a_file_that_is_not_a_kernel_stops_the_run_naming_it(which, inputs):
    """CSPICE's ``furnsh`` takes a text note or a PNG for an empty text kernel: the run answered exit 0."""
    import spiceypy

    from jaxlimb.errors import SpiceError
    from jaxlimb.geometry.spice import loaded_kernels

    with pytest.raises(SpiceError, match=f"{inputs[which].name}.* is not a SPICE kernel"):
        with loaded_kernels([inputs[which]]):
            pass
    assert spiceypy.ktotal("ALL") == 0  # nothing left in the kernel pool
    if not (CASSINI / "N1511803932_1.IMG").is_file():
        pytest.skip("shared Cassini data not present")
    kernels = sorted(str(p) for p in (CASSINI / "kernels").iterdir())
    res = run_cli(["locate", CASSINI / "N1511803932_1.IMG", "--kernels", *kernels, inputs[which], "--json"])
    obj = assert_refused(res, 2, inputs[which].name, check="spice")
    assert "not a SPICE kernel" in obj["message"] and spiceypy.ktotal("ALL") == 0


# ----------------------------------------------------------------------------- meshes
_OCTA_V = "v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
_OCTA_F = ["1 3 5", "3 2 5", "2 4 5", "4 1 5", "3 1 6", "2 3 6", "4 2 6", "1 4 6"]


def _bow_tie() -> str:
    """Two octahedra touching at one vertex (the first's +x tip is the second's -x tip)."""
    second = "v 3 0 0\nv 2 1 0\nv 2 -1 0\nv 2 0 1\nv 2 0 -1\n"  # vertices 7..11; its -x tip is vertex 1
    idx = {"1": "7", "2": "1", "3": "8", "4": "9", "5": "10", "6": "11"}
    faces = [f"f {f}" for f in _OCTA_F] + ["f " + " ".join(idx[i] for i in f.split()) for f in _OCTA_F]
    return _OCTA_V + second + "\n".join(faces) + "\n"


@pytest.mark.parametrize(("name", "text", "expect"), [
    ("zero.obj", _OCTA_V + "\n".join(f"f {f}" for f in _OCTA_F).replace("f 4 2 6", "f 4 2 0") + "\n", "index 0"),
    ("bowtie.obj", _bow_tie(), "bow-tie"),
    ("huge.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                 "element face 2000000\nproperty list uchar int vertex_indices\nend_header\n", "2000000 faces"),
])
def test_mesh_that_is_not_a_closed_manifold_of_bounded_size_exits_2(name, text, expect, tmp_path):
    mesh = tmp_path / name
    mesh.write_text(text)
    res = run_cli(["los", "build-db", mesh, "--out", tmp_path / "db.npz", "--json", "--no-progress"])
    obj = assert_refused(res, 2, name, check="bad_mesh")
    assert expect in obj["message"] and not (tmp_path / "db.npz").exists()


# ----------------------------------------------------------------------------- outputs that are not files
def test_fifo_and_device_outputs_are_refused_up_front(inputs, tmp_path):
    fifo = tmp_path / "out.jsonl"
    os.mkfifo(fifo)
    result = {}
    argvs = {"fifo": ["los", "locate", inputs["moon.png"], "--db", inputs["db.npz"], "--camera",
                      inputs["camera.json"], "--out", fifo, "--json"],
             "full": ["los", "locate", inputs["moon.png"], "--db", inputs["db.npz"], "--camera",
                      inputs["camera.json"], "--out", "/dev/full", "--json"],
             "build": ["los", "build-db", inputs["mesh.obj"], "--out", "/dev/null", "--json", "--no-progress"]}
    worker = threading.Thread(target=lambda: result.update({k: run_cli(v) for k, v in argvs.items()}), daemon=True)
    worker.start()
    worker.join(timeout=60)
    if worker.is_alive():  # a FIFO without a reader blocks an open for writing: unblock, then fail
        os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
        pytest.fail("an --out FIFO blocked the command")
    for key, name in (("fifo", "out.jsonl"), ("full", "/dev/full"), ("build", "/dev/null")):
        obj = assert_refused(result[key], 2, name)
        assert "not a regular file" in obj["message"] or "extension" in obj["message"]


# ----------------------------------------------------------------------------- --resume of another run
def _db(inputs, tmp_path):  # noqa: ANN001, ANN202
    db = tmp_path / "db.npz"
    res = run_cli(["los", "build-db", inputs["mesh.obj"], "--out", db, "--step-deg", "30", "--template-size", "64",
                   "--json", "--no-progress"])
    assert res.code == 0, res
    return db


def test_resume_refuses_a_file_of_another_camera_command_or_garbage(inputs, tmp_path):
    db = _db(inputs, tmp_path)
    out = tmp_path / "run.jsonl"
    base = ["los", "locate", inputs["moon.png"], inputs["black.png"], "--db", db, "--camera", inputs["camera.json"],
            "--no-refine", "--out", out]
    assert run_cli(base).code in (0, 3)
    good = out.read_text()
    assert len(good.splitlines()) == 2 and all(json.loads(s)["run_settings"] for s in good.splitlines())
    other_camera = tmp_path / "camera2.json"
    other_camera.write_text(json.dumps({**json.loads(inputs["camera.json"].read_text()), "focal_length_mm": 0.6}))
    cases = {
        "camera": (base[:6] + ["--camera", other_camera] + base[8:], good),
        "options": (base[:-2] + ["--step-deg", "20", "--out", out], good),  # not refined: step is a setting too
        "command": (base, good.replace(json.loads(good.splitlines()[0])["run_settings"], "0123456789abcdef")),
        "garbage": (base, good + "this is not a record\n"),
        "foreign": (base, json.dumps({"status": "ok", "image": str(inputs["moon.png"])}) + "\n"),
    }
    for name, (argv, content) in cases.items():
        out.write_text(content)
        res = run_cli([*argv, "--resume", "--json"])
        obj = assert_refused(res, 2, "--resume", check="bad_config")
        assert ("not a frame record" in obj["message"]) == (name == "garbage"), name
        assert out.read_text() == content  # nothing appended to a file that is not this run's
    out.write_text(good + '{"status": "ok", "cent')  # the partial line a crash leaves: cut, then resumed
    res = run_cli([*base, "--resume"])
    assert res.code in (0, 3) and out.read_text() == good and "0 frames" in res.err


# ----------------------------------------------------------------------------- bounds --help states
def test_montecarlo_annulus_and_batch_bounds_are_the_enforced_ones():
    import argparse

    from jaxlimb.cli._montecarlo import _batch_size
    from jaxlimb.cli._study_args import RANGES

    res = run_cli(["montecarlo", "--annulus", "5e-324", "--json"])  # inside (0, 1000]: LinAlgError, exit 1
    assert_refused(res, 2, "--annulus", check="bad_arguments")
    assert f"px {RANGES['annulus']} (default 6" in " ".join(run_cli(["montecarlo", "--help"]).out.split())
    ns = argparse.Namespace(batch=100_000, n=2, resume=False)
    assert _batch_size(ns) == 2  # --n 2 --batch 100000 compiled 100 000 fits (86 s)
    assert _batch_size(argparse.Namespace(batch=None, n=1000, resume=False)) == 250
    assert _batch_size(argparse.Namespace(batch=100_000, n=2, resume=True)) == 100_000  # a resumed study's own
