"""The ``jaxlimb locate`` command-line contract of docs/design.md, end to end.

Exit 0 with one JSON object on stdout; exit 2 (unusable input) or 3 (failed check) with
``{"status": "error", "check": NAME, "message": TEXT}`` on stdout under ``--json``, else one
line on stderr; never a traceback.  Most cases run ``jaxlimb.cli.main`` in-process (the
compiled fits are shared); one runs the real executable in a subprocess.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest

from jaxlimb._schema import validate
from jaxlimb.cli import main
from jaxlimb.pipeline import covariance_block

from ._scenes import SMALL_CAMERA, scene, sun_hints


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    img, tr = scene(30000.0, 30.0, (190.0, 260.0), 20.0, "uniform")
    cv2.imwrite(str(d / "moon.png"), img)
    (d / "camera.json").write_text(json.dumps(SMALL_CAMERA.to_dict()))
    (d / "hints.json").write_text(json.dumps({"body": "moon", "sun_dir_camera": list(map(float, tr.sun_dir_cam)),
                                              "range_prior_km": 31000.0, "unknown_key": 1}))
    (d / "empty.png").write_bytes(b"")
    raw = (d / "moon.png").read_bytes()
    (d / "truncated.png").write_bytes(raw[: len(raw) // 2])
    cv2.imwrite(str(d / "one.png"), np.zeros((1, 1), np.uint8))
    cv2.imwrite(str(d / "black.png"), np.zeros((400, 500), np.uint8))
    cv2.imwrite(str(d / "white.png"), np.full((400, 500), 255, np.uint8))
    cv2.imwrite(str(d / "noise.png"), np.random.default_rng(0).integers(0, 256, (400, 500)).astype(np.uint8))
    tiny, _ = scene(1737.4 * 1403.0, 0.0, (200.0, 250.0))
    cv2.imwrite(str(d / "tiny.png"), tiny)
    big, _ = scene(7000.0, 0.0, (200.0, 250.0))
    cv2.imwrite(str(d / "filling.png"), big)
    (d / "bad_camera.json").write_text("{not json")
    (d / "bad_camera_keys.json").write_text(json.dumps({"focal_length_mm": -1, "pixel_pitch_mm": 0.0022, "rows": 400, "cols": 500}))
    (d / "bad_hints.json").write_text("[1, 2")
    (d / "bad_hints_value.json").write_text(json.dumps({"sun_dir_camera": [0, 0]}))
    return d, tr


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_success_json(files, capsys):
    d, tr = files
    code, out, err = _run(capsys, "locate", d / "moon.png", "--camera", d / "camera.json", "--hints", d / "hints.json", "--json")
    assert code == 0, (out, err)
    lines = out.strip().splitlines()
    assert len(lines) == 1
    j = json.loads(lines[0])
    assert j["status"] == "ok"
    validate(j, "result", "locate --json")  # jaxlimb/schemas/result.schema.json
    for key in ("center_rc", "radius_px", "k", "ymax", "ymin", "covariance", "iterations", "solver", "front_end",
                "n_pixels", "los_camera", "range_km"):
        assert key in j, key
    assert np.hypot(*np.subtract(j["center_rc"], tr.center_rc)) < 0.05
    assert j["range_km"] == pytest.approx(tr.range_km, rel=2e-3)
    assert j["front_end"] == "gradient" and isinstance(j["solver"], str) and j["iterations"] >= 1


def test_success_variants(files, capsys):
    d, tr = files
    code, out, _ = _run(capsys, "locate", d / "moon.png", "--front-end", "scanline", "--model", "ellipse", "--json")
    assert code == 0
    j = json.loads(out)
    validate(j, "result", "locate --json")
    assert j["front_end"] == "scanline" and set(j["ellipse"]) == {"center_rc", "semi_axes_px", "angle_rad"}
    assert "radius_px" not in j and "range_km" not in j  # no camera: no range
    code, out, err = _run(capsys, "locate", d / "moon.png")  # human-readable
    assert code == 0 and "centre (row, col)" in out and err == ""


CASES = [
    ("missing.png", (), 2, "bad_image"),
    ("empty.png", (), 2, "bad_image"),
    ("truncated.png", (), 2, "bad_image"),
    ("one.png", (), 2, "bad_image"),
    ("black.png", (), 3, "no_body"),
    ("white.png", (), 3, "no_body"),
    ("noise.png", (), 3, "no_body"),
    ("tiny.png", (), 3, "too_small"),
    ("filling.png", (), 3, "too_big"),
    ("moon.png", ("--camera", "bad_camera.json"), 2, "bad_config"),
    ("moon.png", ("--camera", "bad_camera_keys.json"), 2, "bad_config"),
    ("moon.png", ("--camera", "missing_camera.json"), 2, "bad_config"),
    ("moon.png", ("--hints", "bad_hints.json"), 2, "bad_config"),
    ("moon.png", ("--hints", "bad_hints_value.json"), 2, "bad_config"),
    ("moon.png", ("--solver", "nope"), 2, "bad_arguments"),
    ("moon.png", ("--sun-declination-max", "100"), 2, "bad_arguments"),
    ("moon.png", ("--unresolved-glow", "0.4"), 2, "bad_arguments"),
    ("moon.png", ("--unresolved-glow", "0.4,-3,25"), 2, "bad_arguments"),
    ("moon.png", ("--unresolved-glow", "0.4,25,6"), 2, "bad_arguments"),
    ("moon.png", ("--unresolved-glow", "nan,6,25"), 2, "bad_arguments"),
    ("moon.png", ("--max-center-sigma-px", "0"), 2, "bad_arguments"),
    ("moon.png", ("--max-center-sigma-px", "-1"), 2, "bad_arguments"),
    ("moon.png", ("--max-center-sigma-px", "inf"), 2, "bad_arguments"),
    ("moon.png", ("--max-center-sigma-px", "1e-6"), 3, "center_too_uncertain"),
]


@pytest.mark.parametrize("name, extra, code, check", CASES)
def test_failures_json_and_plain(files, capsys, name, extra, code, check):
    d, _ = files
    extra = [d / e if e.endswith(".json") else e for e in extra]
    got, out, err = _run(capsys, "locate", d / name, *extra, "--json")
    assert got == code, (out, err)
    lines = out.strip().splitlines()
    assert len(lines) == 1, out
    j = json.loads(lines[0])
    assert j["status"] == "error" and j["check"] == check and isinstance(j["message"], str) and j["message"]
    assert "Traceback" not in out + err
    got, out, err = _run(capsys, "locate", d / name, *extra)
    assert got == code and out == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_center_tolerance_is_the_users(files, capsys):
    """``--max-center-sigma-px``: the same frame is refused under a tolerance below its centre sigma (the message
    names the flag) and answered, with the same covariance, under one above it or ``none``."""
    d, _ = files
    base = ["locate", d / "moon.png", "--camera", d / "camera.json", "--hints", d / "hints.json", "--json"]
    code, out, _ = _run(capsys, *base)
    assert code == 0
    j = json.loads(out)
    s = np.sqrt(max(np.linalg.eigvalsh(covariance_block(j["covariance"]))))
    code, out, _ = _run(capsys, *base, "--max-center-sigma-px", f"{0.5 * s:.6g}")
    r = json.loads(out)
    assert code == 3 and r["check"] == "center_too_uncertain" and "--max-center-sigma-px" in r["message"]
    for tol in (f"{2 * s:.6g}", "none", "NONE"):
        code, out, _ = _run(capsys, *base, "--max-center-sigma-px", tol)
        assert code == 0 and json.loads(out)["covariance"] == j["covariance"]


def test_real_process_no_traceback(files):
    d, _ = files
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("JAXLIMB_DEBUG", None)
    p = subprocess.run([sys.executable, "-m", "jaxlimb.cli", "locate", str(d / "truncated.png"), "--json"],
                       capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 2
    assert json.loads(p.stdout)["check"] == "bad_image"
    assert "Traceback" not in p.stderr
    p = subprocess.run([sys.executable, "-m", "jaxlimb.cli", "locate", str(d / "black.png")],
                       capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 3 and p.stdout == "" and len(p.stderr.strip().splitlines()) == 1


def test_figure(files, tmp_path):
    from jaxlimb.pipeline import locate, save_locate_figure

    img, tr = scene(30000.0, 30.0, (190.0, 260.0), 20.0, "uniform")
    m = locate(img, SMALL_CAMERA)
    out = tmp_path / "fig.png"
    save_locate_figure(img, m, out, truth=tr)
    a = cv2.imread(str(out))
    assert a is not None and a.shape[0] > 200 and a.shape[1] > 400
    assert not list(tmp_path.glob(".fig.png.*"))  # atomic: no temporary left behind


def test_edge_residuals_see_a_centre_error_as_its_sinusoid():
    """The figure's residual panel: the image's own edge along the fitted limb's normals is on the fitted limb
    (median within 0.01 px on a uniform disc), and a limb moved by 0.5 px in col leaves -0.5 cos(angle)."""
    import dataclasses

    from jaxlimb.pipeline import locate
    from jaxlimb.pipeline.figure import edge_residuals

    img, tr = scene(30000.0, 30.0, (190.0, 260.0), 20.0, "uniform")
    m = locate(img, SMALL_CAMERA, sun_hints(tr))
    ang, res = edge_residuals(img, m)
    assert ang.size > 100 and abs(np.median(res)) < 0.01 and np.std(res) < 0.1
    le = dict(m.extras["limb_ellipse"])
    le["center_rc"] = [le["center_rc"][0], le["center_rc"][1] + 0.5]
    ang, res = edge_residuals(img, dataclasses.replace(m, extras={**m.extras, "limb_ellipse": le}))
    a = np.radians(ang)
    coef = np.linalg.lstsq(np.column_stack([np.ones_like(a), np.cos(a), np.sin(a)]), res, rcond=None)[0]
    assert coef[1] == pytest.approx(-0.5, abs=0.03) and abs(coef[0]) < 0.03 and abs(coef[2]) < 0.05
