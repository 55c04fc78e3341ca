"""Hostile input and output paths for every sub-command, checked before any computation.

Inputs: missing files, directories, empty files, garbage bytes, truncated images, a text
file, a binary "OBJ", a mesh with a NaN vertex -- each must exit 2 with the typed check of
its role (``bad_image``, ``bad_mesh``, ``bad_database``, ``bad_config``) and a message naming
the file.  Outputs (``--out``, ``--figure``, ``--plot``): a missing directory, a directory, an
unknown extension, a path under a regular file, an unwritable place -- exit 2 naming the flag,
and no output file appears.
"""

from __future__ import annotations

import itertools

import pytest

from ._cli import assert_refused, run_cli

BAD_IMAGES = ["missing", "dir", "empty.png", "garbage.png", "truncated.png", "text.txt", "mesh.obj"]
BAD_MESHES = ["missing", "dir", "empty.png", "garbage.obj", "nan.obj", "text.txt", "moon.png"]
BAD_DBS = ["missing", "dir", "empty.png", "garbage.npz", "moon.png", "text.txt"]


def _image_argv(command: str, image, f: dict) -> list:
    return {
        "locate": ["locate", image, "--json"],
        "posterior": ["posterior", image, "--json"],
        "posterior-npy": ["posterior", str(image) + ".npy" if image == f["missing"] else image, "--center-rc", "1", "1",
                          "--radius", "5", "--json"],
        "navigate": ["navigate", image, "--camera", f["camera.json"], "--epoch", "2026-01-01T00:00:00Z",
                     "--attitude", "[0, 0, 0, 1]", "--json"],
        "los-locate": ["los", "locate", image, "--db", f["db.npz"], "--camera", f["camera.json"], "--json"],
    }[command]


@pytest.mark.parametrize(("command", "which"), itertools.product(
    ("locate", "posterior", "posterior-npy", "navigate", "los-locate"), BAD_IMAGES))
def test_unusable_image_exits_2(command, which, inputs):
    res = run_cli(_image_argv(command, inputs[which], inputs))
    assert_refused(res, 2, (inputs[which].name, "image"), check=None)


@pytest.mark.parametrize(("command", "which"), itertools.product(("build-db", "los-locate"), BAD_MESHES))
def test_unusable_mesh_exits_2_with_a_clear_message(command, which, inputs, tmp_path):
    argv = (["los", "build-db", inputs[which], "--out", tmp_path / "db.npz", "--json", "--no-progress"]
            if command == "build-db" else
            ["los", "locate", inputs["moon.png"], "--mesh", inputs[which], "--camera", inputs["camera.json"], "--json"])
    obj = assert_refused(run_cli(argv), 2, inputs[which].name, check="bad_mesh")
    message = obj["message"]
    assert "ModuleNotFoundError" not in message and "charset" not in message
    expect = {"dir": "directory", "missing": "does not exist", "garbage.obj": "not a mesh", "nan.obj": "not finite"}
    assert expect.get(which, "") in message
    assert not (tmp_path / "db.npz").exists()


@pytest.mark.parametrize("which", BAD_DBS)
def test_unusable_database_exits_2(which, inputs):
    argv = ["los", "locate", inputs["moon.png"], "--db", inputs[which], "--camera", inputs["camera.json"], "--json"]
    obj = assert_refused(run_cli(argv), 2, inputs[which].name, check="bad_database")
    assert ("directory" in obj["message"]) == (which == "dir")


OUT_CASES = ["missing-dir", "a-dir", "bad-ext", "under-file", "proc"]


def _out_path(kind: str, f: dict, ext: str):
    return {"missing-dir": f["missing"].with_suffix(ext), "a-dir": f["dir"], "bad-ext": f["dir"] / "x.xyz",
            "under-file": f["under_file"].with_suffix(ext), "proc": f"/proc/jaxlimb-fuzz{ext}"}[kind]


@pytest.mark.parametrize(("command", "kind"), itertools.product(("build-db", "locate", "posterior"), OUT_CASES))
def test_unwritable_output_exits_2_before_any_computation(command, kind, inputs):
    ext = ".npz" if command == "build-db" else ".png"
    out = _out_path(kind, inputs, ext)
    argv, flag = {
        # a mesh that would take minutes (--step-deg 0.5): the refusal must come first
        "build-db": (["los", "build-db", inputs["mesh.obj"], "--step-deg", "0.5", "--out", out, "--json"], "--out"),
        "locate": (["locate", inputs["moon.png"], "--figure", out, "--json"], "--figure"),
        "posterior": (["posterior", inputs["moon.png"], "--plot", out, "--json"], "--plot"),
    }[command]
    assert_refused(run_cli(argv), 2, flag)
    assert not (inputs["missing"].parent.exists())


@pytest.mark.parametrize(("command", "kind"), itertools.product(("demo", "figures"), ("a-file", "under-file")))
def test_output_directory_that_cannot_be_one_exits_2(command, kind, inputs):
    out = inputs["text.txt"] if kind == "a-file" else inputs["under_file"]
    assert_refused(run_cli([command, "--out", out] + (["--json"] if command == "demo" else [])), 2, "--out",
                   json_mode=command == "demo")


def test_figures_out_is_relative_to_the_current_directory(tmp_path, monkeypatch):
    """``jaxlimb figures --out rel`` writes under the caller's directory, not the checkout."""
    from jaxlimb.cli import _figures

    script = tmp_path / "paper_figures" / "make_all.py"
    script.parent.mkdir()
    record = tmp_path / "argv.txt"
    script.write_text(f"import sys; open({str(record)!r}, 'w').write(sys.argv[sys.argv.index('--out') + 1])\n")
    monkeypatch.setattr(_figures, "_SCRIPT", script)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    res = run_cli(["figures", "--quick", "--out", "figs"])
    assert res.code == 0, res
    assert record.read_text() == str(work / "figs")


@pytest.mark.parametrize("which", ["missing", "dir", ""])
def test_demo_sdo_that_is_not_a_file_exits_2_before_the_demo(which, inputs, tmp_path):
    sdo = inputs[which] if which else ""
    res = run_cli(["demo", "--out", tmp_path / "demo", "--sdo", sdo, "--json"])
    assert_refused(res, 2, "--sdo")
    assert not (tmp_path / "demo").exists()
