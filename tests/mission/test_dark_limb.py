"""Check "dark limb": a lit-limb circle the visible dark limb contradicts is a typed failure."""

import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.cli import main
from jaxlimb.errors import DarkLimbInconsistentError
from jaxlimb.pipeline.sphere.dark_limb import check_dark_limb, dark_limb_offset

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_whole_limb import _render  # noqa: E402


def test_dark_limb_on_the_true_circle_passes_and_off_it_fails():
    img, ic = _render((250.3, 262.7), seed=3, crescent_dn=0.0)  # dark disc 3 DN below the sky
    c, r = ic.center_rc, float(np.sqrt(np.prod(ic.semi_axes_px)))
    d = check_dark_limb(img, c, r)
    assert d["n_bins"] > 300 and abs(d["median_offset_px"]) < 1.0
    with pytest.raises(DarkLimbInconsistentError, match="inside the circle"):
        check_dark_limb(img, (c[0] - 6.0, c[1]), r + 8.0)


def test_no_dark_limb_on_a_black_sky():
    pipeline = str(Path(__file__).resolve().parents[1] / "pipeline")
    sys.path.insert(0, pipeline)
    from _scenes import scene

    img, truth = scene(20000.0, 20.0, (200.0, 250.0))
    d = dark_limb_offset(img, truth.center_rc, truth.apparent_radius_px + 10.0)
    assert d["n_bins"] < 20  # the check does not apply: nothing contradicts the lit limb


def test_enceladus_without_kernels_is_a_typed_failure(tmp_path):
    """The issue's confident wrong answer (304.6 px, ~15 px outside the dark disc): now exit 3."""
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"focal_length_mm": 2002.7, "pixel_pitch_mm": 0.012, "rows": 1024, "cols": 1024}))
    hints = tmp_path / "hints.json"
    hints.write_text(json.dumps({"body": "enceladus", "range_prior_km": 144191}))
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["locate", str(shared_data_dir() / "cassini" / "N1511803932_1.IMG"), "--camera", str(cam),
                     "--hints", str(hints), "--json"])
    out = json.loads(buf.getvalue())
    assert code == 3, out
    assert out["check"] == "dark_limb_inconsistent"


def test_jpeg_blocks_on_a_black_sky_are_not_a_dark_limb():
    """8-bit JPEG of a crescent on a black sky: blocks and quantisation steps give 'edges' where the
    disc is darker than the sky, but the sky is no brighter than the disc across them (0.1 sigma)."""
    import cv2

    pipeline = str(Path(__file__).resolve().parents[1] / "pipeline")
    sys.path.insert(0, pipeline)
    from _scenes import scene

    img, truth = scene(60000.0, 140.0, (300.0, 400.0))
    q = np.clip(np.rint(img / img.max() * 200 + 1), 0, 255).astype(np.uint8)
    jpeg = cv2.imdecode(cv2.imencode(".jpg", q, [cv2.IMWRITE_JPEG_QUALITY, 78])[1], cv2.IMREAD_GRAYSCALE)
    r = truth.apparent_radius_px - 2.0  # a lit-limb circle 2 px small: the artefacts lie > 3 px outside it
    d = check_dark_limb(jpeg.astype(float), truth.center_rc, r)  # no DarkLimbInconsistentError
    assert d["n_bins"] >= 20 and d["median_offset_px"] > d["limit_px"]  # what the count and offset alone flag
    assert not d["is_limb"] and abs(d["median_contrast_dn"]) < d["noise_dn"]
