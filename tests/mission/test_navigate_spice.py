"""``jaxlimb navigate --kernels``: the same SPICE hints as ``locate``, the observer relative to the body."""

import contextlib
import io
import json

import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.cli import main

CASSINI = shared_data_dir() / "cassini"
KERNELS = sorted(str(p) for p in (CASSINI / "kernels").iterdir())


def _run(argv):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    return code, buf.getvalue()


def test_navigate_with_kernels_places_the_observer_beside_spice():
    code, out = _run(["navigate", str(CASSINI / "N1511803932_1.IMG"), "--kernels", *KERNELS, "--json"])
    assert code == 0, out
    r = json.loads(out)
    assert r["status"] == "ok" and r["body"] == "enceladus" and r["attitude"].startswith("SPICE CK")
    pos, ref = np.array(r["position_km"]), np.array(r["spice_observer_km"])
    u = ref / np.linalg.norm(ref)
    d = pos - ref
    # across the line of sight: the pointing residual (~10 px x 6 urad/px x 144 000 km ~ 9 km)
    assert np.linalg.norm(d - (d @ u) * u) < 20.0
    # along it: the range from the dark limb's apparent size (IAU 2015 radii, not the kernels' 2002 ones), within 2
    # of its sigma, which carries the IK's focal-length uncertainty (cas_iss_v08.ti: 4.4 mm of 2000 mm) one to one
    P = np.array(r["covariance_km2"])
    assert abs(d @ u) < 2.0 * np.sqrt(u @ P @ u)
    Ps = np.array(r["covariance_parts_km2"]["camera_scale"])
    assert np.sqrt(u @ Ps @ u) == pytest.approx(4.4 / 2000.0 * r["range_km"], rel=1e-3)
    assert r["spice"]["predicted"]["radii_source"] == "iau2015"
    assert r["spice"]["measured_minus_predicted"]["delta_px"] < 15.0
    sig = np.array(r["sigma_km"])
    assert (sig > 0).all() and np.allclose(np.array(r["covariance_km2"]), np.array(r["covariance_km2"]).T)


def test_navigate_without_kernels_needs_camera_epoch_attitude():
    code, _ = _run(["navigate", str(CASSINI / "N1511803932_1.IMG"), "--json"])
    assert code == 2


def test_navigate_with_kernels_refuses_an_epoch():
    code, _ = _run(["navigate", str(CASSINI / "N1511803932_1.IMG"), "--kernels", *KERNELS,
                    "--epoch", "2005-11-27T17:03:10Z", "--json"])
    assert code == 2


@pytest.mark.parametrize("bad", [["--kernels", "/nonexistent/meta.tm"], ["--body", "vulcan", "--kernels", *KERNELS]])
def test_navigate_bad_spice_input_exits_2(bad):
    code, _ = _run(["navigate", str(CASSINI / "N1511803932_1.IMG"), *bad, "--json"])
    assert code == 2
