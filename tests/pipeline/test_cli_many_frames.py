"""``jaxlimb locate`` on many frames: JSON Lines, per-frame errors, --out/--resume."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from jaxlimb._schema import validate
from jaxlimb.cli import main

from ._scenes import SMALL_CAMERA, scene


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    d = tmp_path_factory.mktemp("many")
    (d / "imgs").mkdir()
    for i, (r, c) in enumerate([(190.0, 260.0), (205.0, 240.0), (180.0, 275.0)]):
        img, tr = scene(30000.0, 30.0, (r, c), 20.0, "uniform")
        cv2.imwrite(str(d / "imgs" / f"f{i}.png"), img)
    (d / "camera.json").write_text(json.dumps(SMALL_CAMERA.to_dict()))
    (d / "hints.json").write_text(json.dumps({"body": "moon"}))
    raw = (d / "imgs" / "f0.png").read_bytes()
    (d / "bad").mkdir()
    (d / "bad" / "truncated.png").write_bytes(raw[: len(raw) // 2])
    cv2.imwrite(str(d / "bad" / "black.png"), np.zeros((400, 500), np.uint8))
    (d / "notes.txt").write_text("not an image")
    return d


def _lines(text: str) -> list[dict]:
    return [json.loads(s) for s in text.splitlines() if s.strip()]


def _args(d, *images):
    return ["locate", *map(str, images), "--camera", str(d / "camera.json"), "--hints", str(d / "hints.json")]


def test_directory_streams_one_line_per_frame_equal_to_single_runs(frames, capsys):
    d = frames
    assert main(_args(d, d / "imgs")) == 0
    recs = _lines(capsys.readouterr().out)
    assert [r["image"] for r in recs] == [str(d / "imgs" / f"f{i}.png") for i in range(3)]
    assert all(r["status"] == "ok" for r in recs)
    for r in recs:  # every JSON line is a record of jaxlimb/schemas/result.schema.json
        validate(r, "result", "locate JSON line")
    assert all(r["timing"]["compile_s"] <= r["timing"]["seconds"] for r in recs)  # compile time reported apart
    assert main([*_args(d, d / "imgs" / "f1.png"), "--json"]) == 0
    single = json.loads(capsys.readouterr().out)
    assert "image" not in single  # one image: the single-frame contract, unchanged
    assert recs[1]["center_rc"] == pytest.approx(single["center_rc"], abs=1e-9)
    assert single["timing"]["compile_s"] >= 0 and single["timing"]["seconds"] > 0


def test_bad_frames_give_error_lines_and_the_run_goes_on(frames, capsys):
    d = frames
    lst = d / "list.txt"
    lst.write_text(f"# frames\n{d / 'imgs' / 'f0.png'}\n\n{d / 'bad' / 'black.png'}\n{d / 'imgs' / 'f2.png'}\n")
    assert main(_args(d, f"@{lst}")) == 3  # a failed check, nothing unusable
    recs = _lines(capsys.readouterr().out)
    assert [r["status"] for r in recs] == ["ok", "error", "ok"]
    assert recs[1]["image"].endswith("black.png") and recs[1]["check"] and recs[1]["message"]
    validate(recs[1], "result", "locate JSON line")  # an error line is a record of the schema too
    code = main(_args(d, str(d / "bad" / "*.png"), d / "imgs" / "f0.png"))  # a quoted glob + a file
    out, err = capsys.readouterr()
    assert code == 2  # the truncated PNG is unusable input: the worst
    recs = _lines(out)
    assert {r["image"].rsplit("/", 1)[-1]: r["status"] for r in recs} == {"black.png": "error", "truncated.png": "error",
                                                                         "f0.png": "ok"}
    assert "Traceback" not in err and "3 frames: 1 ok, 2 failed" in err


def test_out_and_resume_skip_done_frames_and_cut_a_partial_line(frames, capsys):
    d = frames
    out = d / "run.jsonl"
    assert main([*_args(d, d / "imgs" / "f0.png", d / "imgs" / "f1.png"), "--out", str(out)]) == 0
    assert capsys.readouterr().out == ""
    assert len(_lines(out.read_text())) == 2
    with open(out, "a") as fh:
        fh.write('{"status": "ok", "center_rc": [1')  # the write a crash interrupted
    assert main([*_args(d, d / "imgs"), "--out", str(out)]) == 2  # exists: refused without --resume
    assert "--resume" in capsys.readouterr().err
    assert main([*_args(d, d / "imgs"), "--out", str(out), "--resume"]) == 0
    err = capsys.readouterr().err
    assert "1 frames: 1 ok, 0 failed, 2 already in" in err
    recs = _lines(out.read_text())
    assert [r["image"].rsplit("/", 1)[-1] for r in recs] == ["f0.png", "f1.png", "f2.png"]


@pytest.mark.parametrize("argv, match", [(["--resume"], "--out"), (["--figure", "x.png"], "--figure")])
def test_bad_combinations_are_exit_2(frames, capsys, argv, match):
    d = frames
    assert main([*_args(d, d / "imgs"), *argv, "--json"]) == 2
    assert match in json.loads(capsys.readouterr().out)["message"]


def test_empty_pattern_and_directory(frames, capsys):
    d = frames
    assert main([*_args(d, str(d / "nothing*.png")), "--json"]) == 2
    assert "matches no file" in capsys.readouterr().out
    (d / "emptydir").mkdir(exist_ok=True)
    assert main([*_args(d, d / "emptydir"), "--json"]) == 2
    assert "no image files" in capsys.readouterr().out


def test_frames_on_a_dask_scheduler_equal_in_process(frames, capsys):
    from dask.distributed import LocalCluster

    d = frames
    assert main(_args(d, d / "imgs")) == 0
    ref = _lines(capsys.readouterr().out)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        assert main([*_args(d, d / "imgs", d / "bad" / "black.png"), "--scheduler", cluster.scheduler_address]) == 3
    recs = _lines(capsys.readouterr().out)
    assert [r["image"] for r in recs[:3]] == [r["image"] for r in ref]  # in order
    assert [r["center_rc"] for r in recs[:3]] == [r["center_rc"] for r in ref]
    assert recs[3]["status"] == "error"


def test_a_label_and_its_image_are_one_frame(tmp_path):
    """A directory of PDS3 pairs (``X.IMG`` + detached ``X.LBL``) and a PDS4 label with its data: one frame each."""
    from jaxlimb.cli._batch import expand_images

    for name in ("a.IMG", "a.LBL", "b.img", "c.LBL", "d.xml", "d.img", "e.png"):
        (tmp_path / name).write_bytes(b"x")
    got = [Path(p).name for p in expand_images([str(tmp_path)])]
    assert got == ["a.IMG", "b.img", "c.LBL", "d.xml", "e.png"]
    assert [Path(p).name for p in expand_images([str(tmp_path / "a.*")])] == ["a.IMG"]
