"""Image bombs: a header that declares a huge image is refused before anything is decoded (exit 2, one line).

Every format jaxlimb reads declares its size in a header (PNG, TIFF and BigTIFF, JPEG, JPEG 2000, BMP, PNM,
FITS, VICAR, PDS3); a file declaring 10^10 pixels, a valid 882 kB PNG that inflates to 30 000 x 30 000 px,
and an image larger than the memory the process may use are refused without the memory a decoder would take
(< 300 MB; their times are measured by ``benchmarks/faults.py``, not asserted here).  A PDS3 label whose
``RECORD_BYTES`` does not fit its data file is a file error, not garbage pixels.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from ._hostile import MAKERS, inflating_png, write_bomb
from ._cli import assert_refused, run_cli

CASSINI = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "cassini"


def _maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


@pytest.mark.parametrize("kind", sorted(MAKERS))
def test_header_bomb_is_refused_before_decoding(kind, tmp_path):
    import astropy.io.fits  # noqa: F401 - the readers' imports are not what is timed
    import vicar  # noqa: F401

    bomb = write_bomb(tmp_path, kind)
    before = _maxrss_mb()
    res = run_cli(["locate", bomb, "--json"])
    obj = assert_refused(res, 2, bomb.name, check="bad_label" if kind == "vicar" else "bad_image")
    assert "100000 x 100000" in obj["message"] or "65535 x 65535" in obj["message"]
    assert _maxrss_mb() - before < 300


def test_valid_inflating_png_is_refused_before_decoding(tmp_path):
    bomb = tmp_path / "inflates.png"
    bomb.write_bytes(inflating_png(30_000, 30_000))  # 882 kB on disk, 900 Mpx (6.7 GiB as float64) decoded
    assert bomb.stat().st_size < 1_000_000
    before = _maxrss_mb()
    for argv in (["locate", bomb, "--json"], ["los", "locate", bomb, "--db", bomb, "--camera", bomb, "--json"]):
        res = run_cli(argv)
        assert_refused(res, 2, "inflates.png", check=None)
    assert _maxrss_mb() - before < 300


def test_small_inflating_png_is_what_it_claims():
    """The bomb maker makes valid PNGs (so the refusal above is of a real image, not a corrupt file)."""
    import cv2
    import numpy as np

    img = cv2.imdecode(np.frombuffer(inflating_png(300, 500), np.uint8), cv2.IMREAD_UNCHANGED)
    assert img.shape == (300, 500) and int(img.max()) == 0


def test_image_larger_than_the_memory_left_is_refused(tmp_path, monkeypatch):
    import jaxlimb._validate as validate

    bomb = write_bomb(tmp_path, "png", rows=4000, cols=4000)  # 16 Mpx: fine on a machine, not in 100 MB
    monkeypatch.setattr(validate, "available_memory", lambda: 100e6)
    obj = assert_refused(run_cli(["locate", bomb, "--json"]), 2, bomb.name, check="bad_image")
    assert "memory" in obj["message"]


def test_a_bomb_in_a_many_frame_run_is_one_error_line(tmp_path, inputs):
    bomb = write_bomb(tmp_path, "tiff")
    out = tmp_path / "o.jsonl"
    res = run_cli(["los", "locate", bomb, inputs["moon.png"], "--db", inputs["db.npz"], "--camera",
                   inputs["camera.json"], "--out", out])
    recs = [json.loads(s) for s in out.read_text().splitlines()]
    assert recs[0]["check"] == "bad_image" and recs[0]["image"] == str(bomb)
    assert res.code == 2 and "Traceback" not in res.err


def test_pds3_label_with_a_wrong_record_bytes_is_a_file_error(tmp_path):
    label = CASSINI / "N1644787857_1.LBL"
    if not label.is_file():
        pytest.skip("shared Cassini data not present")
    text = label.read_text()
    (tmp_path / "N1644787857_1.IMG").symlink_to((CASSINI / "N1644787857_1.IMG").resolve())
    for wrong, expect in (("2048", "FILE_RECORDS x RECORD_BYTES"), ("2072", None)):
        (tmp_path / "N1644787857_1.LBL").write_text(text.replace("RECORD_BYTES = 2072", f"RECORD_BYTES = {wrong}"))
        from jaxlimb.imaging.formats import read_frame

        if expect is None:
            assert read_frame(tmp_path / "N1644787857_1.LBL").data.shape == (1024, 1024)
            continue
        obj = assert_refused(run_cli(["locate", tmp_path / "N1644787857_1.LBL", "--json"]), 2,
                             "N1644787857_1.LBL", check="bad_label")
        assert expect in obj["message"]
    # a FILE_RECORDS that fits but an IMAGE pointer past the end of the data
    bad = text.replace('^IMAGE = ("N1644787857_1.IMG",4)', '^IMAGE = ("N1644787857_1.IMG",40)')
    (tmp_path / "N1644787857_1.LBL").write_text(bad)
    obj = assert_refused(run_cli(["locate", tmp_path / "N1644787857_1.LBL", "--json"]), 2, "N1644787857_1.LBL",
                         check="bad_label")
    assert "past the end" in obj["message"]


_MEASURE = """
import resource, subprocess, sys
p = subprocess.run(sys.argv[1:], capture_output=True, text=True)
u = resource.getrusage(resource.RUSAGE_CHILDREN)
print(p.returncode, u.ru_utime + u.ru_stime, u.ru_maxrss / 1024, repr(p.stdout), repr(p.stderr), sep="|")
"""


def test_bomb_command_process_stays_small_and_quick(tmp_path):
    """The whole ``jaxlimb locate BOMB.png`` process: the header is checked before JAX starts."""
    bomb = tmp_path / "inflates.png"
    bomb.write_bytes(inflating_png(30_000, 30_000))
    env = {k: v for k, v in os.environ.items() if k != "JAXLIMB_DEBUG"}
    out = subprocess.run([sys.executable, "-c", _MEASURE, sys.executable, "-m", "jaxlimb.cli", "locate", str(bomb)],
                         capture_output=True, text=True, env=env, check=True).stdout
    code, cpu_s, rss_mb, stdout, stderr = out.strip().split("|")
    assert int(code) == 2 and eval(stdout) == ""  # noqa: S307 - our own repr
    lines = eval(stderr).splitlines()  # noqa: S307
    assert len(lines) == 1 and lines[0].startswith("jaxlimb: error:") and "inflates.png" in lines[0], lines
    assert float(cpu_s) < 1.0 and float(rss_mb) < 300, (cpu_s, rss_mb)
