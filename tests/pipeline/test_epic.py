"""Real data: the sunlit Earth from deep space (DSCOVR/EPIC natural-colour frames of ``../shared/data/epic``).

Truth (MANIFEST): the L1B product centres the Earth in the frame to about 2 px (``product_center_rc``), and the
apparent radius times the range (the norm of DSCOVR's position) is the same in every frame.  The hints are the
body and a range prior only (no Sun direction, no attitude).  Clouds make the limb, the terminator is near the
edge (phase 4-12 deg) and the interior's cloud edges are sharper than the limb: the gradient front end's strongest
pixels all lie inside the disc until it looks in the band about the lit region's outline.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.geometry.earth import EARTH_EQUATORIAL_KM
from jaxlimb.imaging.formats import read_frame
from jaxlimb.imaging.gradient_front_end import gradient_front_end
from jaxlimb.imaging.io import ColourImageWarning
from jaxlimb.pipeline import locate
from jaxlimb.pipeline.frame import as_camera, as_hints
from jaxlimb.pipeline import covariance_block

EPIC = shared_data_dir() / "epic"
pytestmark = pytest.mark.skipif(not (EPIC / "epic_earth_20221110.png").exists(), reason="EPIC data not available")


def _inputs(stem: str, ext: str):
    read = lambda s: json.loads((EPIC / f"{stem}.{s}.json").read_text())  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ColourImageWarning)  # the JPEG is colour: converted to grey, as the CLI does
        img = read_frame(EPIC / f"{stem}.{ext}").data
    return img, read("camera"), read("hints"), read("metadata")


def test_front_end_finds_the_disc_on_its_outline():
    """The frame whose first circle ran through cloud edges (158 px in a 399 px disc): the retry in the outline band
    finds the limb."""
    img, cam, hints, meta = _inputs("epic_earth_20220510", "png")
    cand = gradient_front_end(img, hints=as_hints(hints), camera=as_camera(cam))
    assert cand.info["outline_retry"]
    assert np.hypot(*np.subtract(cand.center_rc, meta["product_center_rc"])) <= 3.0
    assert abs(cand.radius - 399.0) <= 5.0


def test_locate_epic_png_and_jpeg():
    """Two frames, a PNG and a colour JPEG: located within 3 px of the product centre (its 2 px quality and the
    measurement's sigma cover the error); the apparent semi-major axis times the range is the same in both within
    0.3 %, and within 1 % of the Earth's equatorial radius times the focal length (the limb is cloud tops and haze)."""
    a_range = []
    for stem, ext in (("epic_earth_20221110", "png"), ("epic_earth_20220910", "jpg")):
        img, cam, hints, meta = _inputs(stem, ext)
        m = locate(img, cam, hints)
        e = np.subtract(m.center_rc, meta["product_center_rc"])
        assert np.hypot(*e) <= 3.0, (stem, e)
        c = m.covariance
        P = covariance_block(c) + 2.0**2 * np.eye(2)
        assert float(e @ np.linalg.solve(P, e)) <= 9.0
        a_range.append(m.ellipse.semi_axes_px[0] * meta["range_km"])
        f_px = cam["focal_length_mm"] / cam["pixel_pitch_mm"]
        assert abs(a_range[-1] / (f_px * EARTH_EQUATORIAL_KM) - 1.0) <= 0.01
    assert abs(a_range[0] / a_range[1] - 1.0) <= 3e-3
