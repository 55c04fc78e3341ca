"""The Mimas and Voyager frames that are refused: a correct, explained typed refusal."""

import contextlib
import io
import json

import numpy as np

from jaxlimb._data import shared_data_dir
from jaxlimb.cli import main
from jaxlimb.imaging import detect_body

DATA = shared_data_dir()


def _locate(path):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["locate", str(path), "--json"])
    return code, json.loads(buf.getvalue())


def test_bright_sky_is_measured_above_the_sky():
    """A disc whose shadowed limb is darker than a grey sky: the region is the disc, not the frame."""
    n = 200
    rr, cc = np.mgrid[:n, :n]
    d = np.hypot(rr - 110.0, cc - 95.0)
    img = np.full((n, n), 900.0)
    disc = d < 80
    img[disc] = 500.0 + 1200.0 * np.clip((cc[disc] - 40.0) / 120.0, 0.0, 1.0)  # shadowed at -col, lit at +col
    img += np.random.default_rng(0).normal(0, 5.0, img.shape)
    region = detect_body(img)
    assert region.bright_sky and abs(region.background - 900.0) < 10.0
    assert 0.1 < region.lit_fraction < 0.5


def test_mimas_refusal_is_explained_not_too_big():
    """N1644787857: the sky (~950 DN) is brighter than Mimas' shadowed limb; it was refused as `too_big`
    ("the lit region covers 100 %") -- now a typed failure that says why."""
    code, out = _locate(DATA / "cassini" / "N1644787857_1.LBL")
    assert code == 3, out
    assert out["check"] != "too_big"
    assert "brighter than the body's shadowed limb" in out["message"]


def test_voyager_arc_larger_than_the_frame_says_what_is_missing():
    code, out = _locate(DATA / "voyager" / "C2064922_CALIB.IMG")
    assert code == 3 and out["check"] == "too_big"
    assert "arc of the limb is in the frame" in out["message"] and "range_prior_km" in out["message"]
