"""``jaxlimb track`` end to end on a tiny drawn transfer whose per-frame measurements are already in the
measurements file (the "after locate" mode: ``--resume`` measures nothing), and its input errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jaxlimb.cli import build_parser, main
from jaxlimb.cli._batch import run_settings
from jaxlimb.cli._track import measurement_namespace
from jaxlimb.geometry.attitude import dcm_to_quat
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.ephemeris import epoch_to_jd_tdb
from jaxlimb.track import Propagator, drawn_frames, make_arc, make_transfer, nominal_noise

N = 24


def _write_inputs(tmp_path, n=N):
    jd = epoch_to_jd_tdb("2026-03-07T12:00:00Z")
    arc = make_arc(jd, jd + 3.6)
    cam = Camera(focal_length_mm=2.2, pixel_pitch_mm=0.0022, rows=256, cols=256)
    theta = np.array([cam.focal_px, *cam.principal_point_rc, 0.0])
    tr = make_transfer(arc, Propagator(arc.table), n, theta, 256, 256, rng=np.random.default_rng(5))
    fr = drawn_frames(tr, nominal_noise(tr), np.random.default_rng(3))
    (tmp_path / "camera.json").write_text(json.dumps(cam.to_dict()))
    recs = []
    with open(tmp_path / "frames.jsonl", "w") as ff:
        for k in range(n):
            img = str(tmp_path / f"f{k:03d}.png")
            names = ["center_r", "center_c", "range_km" if tr.bodies[k] == "earth" else "radius"]
            ff.write(json.dumps({"image": img, "epoch": arc.jd0 + tr.t[k] / 86400.0, "body": tr.bodies[k],
                                 "attitude": {"quaternion": dcm_to_quat(fr.C[k]).tolist()},
                                 "true_state": tr.states[k].tolist()}) + "\n")
            recs.append({"status": "ok", "image": img, "center_rc": fr.z[k, :2].tolist(),
                         "covariance": {a: {b: float(fr.R[k][i, j]) for j, b in enumerate(names)}
                                        for i, a in enumerate(names)},
                         ("range_km" if tr.bodies[k] == "earth" else "radius_px"): float(fr.z[k, 2])})
    # the records as track's measurement stage writes them: stamped with the digest of its settings
    args = build_parser().parse_args(["track", "--frames", str(tmp_path / "frames.jsonl"), "--camera",
                                      str(tmp_path / "camera.json")])
    settings = run_settings(measurement_namespace(args, tmp_path / "m.jsonl"))
    (tmp_path / "m.jsonl").write_text("".join(json.dumps({**r, "run_settings": settings}) + "\n" for r in recs))
    return tmp_path


@pytest.mark.slow
def test_track_after_locate(tmp_path, capsys):
    d = _write_inputs(tmp_path)
    code = main(["track", "--frames", str(d / "frames.jsonl"), "--camera", str(d / "camera.json"), "--measurements",
                 str(d / "m.jsonl"), "--resume", "--out", str(d / "t.jsonl"), "--plot", str(d / "t.png"), "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and out["status"] == "ok" and out["frames"] == N and out["failed_frames"] == 0
    lines = [json.loads(x) for x in (d / "t.jsonl").read_text().splitlines()]
    assert len(lines) == N and {"filtered", "smoothed", "batch", "nis", "used"} <= set(lines[0])
    assert (d / "t.png").stat().st_size > 10_000
    assert out["rms_position_error_smoothed_km"] < 50.0
    P = np.array(lines[-1]["smoothed"]["covariance"])
    assert np.allclose(P, P.T) and np.all(np.linalg.eigvalsh(P) > 0)


def test_track_input_errors(tmp_path, capsys):
    (tmp_path / "frames.jsonl").write_text(json.dumps({"image": "a.png", "epoch": 2461100.0}) + "\n")
    (tmp_path / "camera.json").write_text(json.dumps(Camera().to_dict()))
    code = main(["track", "--frames", str(tmp_path / "frames.jsonl"), "--camera", str(tmp_path / "camera.json"), "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 2 and out["status"] == "error" and "needs keys" in out["message"]


@pytest.mark.parametrize("flag", [["--gate-probability", "1.5"], ["--attitude-sigma-urad", "-1"]])
def test_track_bad_flags(tmp_path, flag, capsys):
    code = main(["track", "--frames", "x.jsonl", "--camera", "c.json", *flag])
    assert code == 2


def test_summary_reports_the_camera_with_or_without_a_split():
    # the self-calibrated camera is in the summary whether or not the model error was split (--no-bias: no split)
    from types import SimpleNamespace

    from jaxlimb.cli._track import _summary

    filt = SimpleNamespace(used=np.ones(3, bool), nis=np.ones(3), gate=16.3)
    obs = SimpleNamespace(to_json=lambda: {"observable": [True]})
    fit = SimpleNamespace(t0=0.0, x0=np.zeros(6), P0=np.eye(6), residual_rms=1.0, used=np.ones(3, bool), bias={},
                          camera={"focal_px": {"value": 1000.0, "sigma": 0.1}}, observability=obs)
    split = SimpleNamespace(to_json=lambda: {"moon": {"independent": 0.3, "common": 0.1, "walk": 0.0}})
    for s in (None, split):
        out = _summary(SimpleNamespace(filt=filt, fit=fit, split=s), ["a", "b", "c"], 1.0, None)
        assert out["camera"] == fit.camera and out["observability"] == {"observable": [True]}
        assert ("model_error_split" in out) == (s is not None)


def test_track_takes_every_frame_with_its_covariance_unless_told(tmp_path):
    """``jaxlimb track`` sets no tolerance on a frame's centre sigma (the filter weighs and gates); a tolerance
    given is ``locate``'s, and it changes the measurements' digest (``--resume`` will not mix the two)."""
    base = ["track", "--frames", "f.jsonl", "--camera", "c.json"]
    default, told = build_parser().parse_args(base), build_parser().parse_args([*base, "--max-center-sigma-px", "2"])
    assert default.max_center_sigma_px is None and told.max_center_sigma_px == 2.0
    assert run_settings(measurement_namespace(default, tmp_path / "m.jsonl")) != run_settings(
        measurement_namespace(told, tmp_path / "m.jsonl"))


def test_navigate_passes_a_centre_tolerance_only_when_given():
    from jaxlimb.cli._inputs import locate_options_given

    base = ["navigate", "x.png", "--camera", "c.json"]
    assert locate_options_given(build_parser().parse_args(base)) == {}
    assert locate_options_given(build_parser().parse_args([*base, "--max-center-sigma-px", "none"])) == {
        "max_center_sigma_px": None}
