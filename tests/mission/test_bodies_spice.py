"""Bodies by name, SPICE geometry of the Cassini frames (offline, shared kernels), typed errors."""

import json
import math
import shutil

import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.cli import main
from jaxlimb.errors import SpiceError, UnknownBodyError
from jaxlimb.geometry.bodies import body_from_table, body_radii_km
from jaxlimb.geometry.spice import body_radii, instrument_from, loaded_kernels, spice_body_radii, spice_geometry
from jaxlimb.imaging import Hints

CASSINI = shared_data_dir() / "cassini"
KERNELS = sorted(str(p) for p in (CASSINI / "kernels").iterdir())
T1 = "2005-331T17:03:10.473Z"  # IMAGE_MID_TIME of N1511803932_1


def test_body_table_and_overrides():
    assert body_from_table("Enceladus").radii_km == (256.6, 251.4, 248.3)  # IAU 2015 / pck00011
    assert Hints(body="mimas").radius_km() == pytest.approx((207.8 + 196.7 + 190.6) / 3)
    assert Hints(body="mimas", body_radii_km=(200, 200, 200)).radius_km() == 200
    assert Hints(body="moon").radius_km() == pytest.approx(1737.4)
    with pytest.raises(UnknownBodyError, match="vulcan"):
        body_from_table("vulcan")


def test_table_radii_win_over_an_older_kernel_pck():
    with loaded_kernels(KERNELS):
        r = spice_body_radii("ENCELADUS")
        assert body_radii("ENCELADUS") == (body_radii_km("enceladus"), "iau2015")  # a body the table knows
        assert body_radii("PAN") == (spice_body_radii("PAN"), "kernel")  # one it does not: the kernel pool's
    assert r == pytest.approx((256.3, 247.3, 244.6))  # the Cassini PCK of 2002 (Voyager radii)
    assert r != body_radii_km("enceladus")  # (the table's IAU 2015 radii)
    assert spice_body_radii("ENCELADUS") is None  # unloaded again
    g = spice_geometry(KERNELS, T1, "ISSNA", "ENCELADUS")
    assert (g.radii_km, g.radii_source) == ((256.6, 251.4, 248.3), "iau2015")
    assert g.focal_length_sigma_mm == 4.4  # cas_iss_v08.ti: INS-82360_FL_UNCERTAINTY
    assert g.to_json()["radii_source"] == "iau2015"


def test_cassini_prediction_is_consistent():
    g = spice_geometry(KERNELS, T1, "ISSNA", "ENCELADUS")
    cam = g.camera
    assert (cam.focal_length_mm, cam.pixel_pitch_mm, cam.rows, cam.principal_point_rc) == (2000.0, 0.012, 1024, (511.5, 511.5))
    assert 140_000 < g.range_km < 150_000
    # the disc is near the frame centre, radius ~291 px (MANIFEST: ~288 px, with the 2002 PCK's smaller radii)
    assert abs(g.center_rc[0] - 512) < 40 and abs(g.center_rc[1] - 512) < 60
    r_eq = cam.focal_px * math.tan(math.asin(np.mean(g.radii_km) / g.range_km))
    assert r_eq == pytest.approx(291, abs=3)
    # high phase, crescent toward +row (the lit crescent is at the bottom of the frame)
    s = np.array(g.sun_dir_camera)
    u = np.array(g.body_center_cam) / g.range_km
    assert math.degrees(math.acos(-s @ u)) > 150 and s[1] > 0.2
    R = np.array(g.R_body_to_camera)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0
    h = g.hints()
    assert h.body == "enceladus" and h.range_prior_km == g.range_km


@pytest.mark.parametrize("kw, match", [
    (dict(kernels=["/nonexistent/naif0012.tls"]), "not found"),
    (dict(utc="2010-044T20:46:48.392"), "coverage"),
    (dict(instrument="VOYAGER_ISS_NA"), "unknown instrument"),
    (dict(target="VULCAN"), "VULCAN"),
    (dict(utc=None), "image time"),
])
def test_bad_spice_input_is_typed(kw, match):
    args = dict(kernels=KERNELS, utc=T1, instrument="CASSINI_ISS_NAC", target="ENCELADUS") | kw
    with pytest.raises(SpiceError, match=match):
        spice_geometry(**args)


def test_instrument_names():
    assert instrument_from("issna").spice_name == "CASSINI_ISS_NAC"
    assert instrument_from("CASSINI_ISS_WAC").observer == "CASSINI"


def test_cli_bad_input_exits_2(tmp_path, capsys):
    img = str(CASSINI / "N1511803932_1.IMG")
    assert main(["locate", img, "--kernels", str(tmp_path / "none.tm"), "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "error" and out["check"] == "spice" and "none.tm" in out["message"]
    # an image time outside the coverage: the Mimas frame of 2010 with the 2005 kernels
    assert main(["locate", str(CASSINI / "N1644787857_1.IMG"), "--kernels", *KERNELS, "--json"]) == 2
    assert "coverage" in json.loads(capsys.readouterr().out)["message"]
    assert main(["locate", img, "--body", "vulcan", "--json"]) == 2
    assert json.loads(capsys.readouterr().out)["check"] == "unknown_body"
    # a corrupt label
    bad = tmp_path / "bad.IMG"
    shutil.copy(img, bad)
    with open(bad, "r+b") as fh:
        fh.write(b"LBLSIZE=9999999999")
    assert main(["locate", str(bad), "--json"]) == 2
    assert json.loads(capsys.readouterr().out)["check"] == "bad_label"
