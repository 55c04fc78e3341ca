"""The whole-limb stage (lit + dark limb, predicted shape) on renders with exact truth, and the Cassini frames."""

import math

import numpy as np
import pytest
from scipy import ndimage

from jaxlimb.geometry.attitude import rotation_vector_to_dcm
from jaxlimb.geometry.camera import Camera
from jaxlimb.geometry.ellipsoid import image_conic
from jaxlimb.geometry.hints import Hints
from jaxlimb.pipeline import locate

CAM = Camera(2000.0, 0.012, 512, 512, (255.5, 255.5))
RADII = (256.6, 251.4, 248.3)
R = rotation_vector_to_dcm(np.array([0.3, -0.2, 0.5]))


def _render(center_rc, range_km=300_000.0, seed=0, ss=4, crescent_dn=60.0):
    """A dark triaxial disc on a brighter sky with a lit crescent toward +row (supersampled, PSF 0.8 px, 1 DN noise)."""
    q = range_km * CAM.los(np.asarray(center_rc, float))
    ic = image_conic(CAM, RADII, q, R)
    n = CAM.rows * ss
    g = (np.arange(n) + 0.5) / ss - 0.5
    rr, cc = np.meshgrid(g, g, indexing="ij")
    inside = ic.evaluate(np.stack([rr.ravel(), cc.ravel()], 1)).reshape(n, n) < 0
    b = ic.body_center_rc
    # the crescent: brightness ramps from 0 at a (soft) terminator to 60 DN at the limb, toward +row
    depth = np.hypot(rr - (b[0] - 10.0), cc - b[1]) - math.sqrt(ic.semi_axes_px[0] * ic.semi_axes_px[1])
    crescent = np.where(inside, crescent_dn * np.clip(depth / 10.0, 0.0, 1.0), 0.0)
    img = np.where(inside, 8.0, 11.0) + crescent
    img = ndimage.gaussian_filter(img.reshape(CAM.rows, ss, CAM.cols, ss).mean(axis=(1, 3)), 0.8)  # PSF
    rng = np.random.default_rng(seed)
    return img + rng.normal(0, 1.0, img.shape), ic


def _hints(pred_rc, range_km=300_000.0):
    return Hints(body="enceladus", body_radii_km=RADII, range_prior_km=range_km, R_body_to_camera=R,
                 expected_center_rc=pred_rc, expected_radius_uncertainty_frac=0.05,
                 sun_dir_camera=(0.0, 0.3, 0.95))


def test_whole_limb_recovers_the_center_from_a_wrong_pointing():
    truth = (250.3, 262.7)
    img, ic = _render(truth)
    m = locate(img, CAM, _hints((244.0, 270.0)))  # prediction 10 px off
    err = np.subtract(m.center_rc, ic.body_center_rc)
    assert m.front_end == "predicted"
    # the crescent's inward brightness ramp biases the flat-topped sigmoid by ~0.35 px (module docstring)
    assert np.hypot(*err) < 0.5, err
    assert m.range_km == pytest.approx(300_000.0, rel=0.006)
    bins = m.extras["angular_bins"]
    assert bins["bins_dark"] > 15 and bins["bins_lit"] > 15, bins  # both polarities measured


def test_masked_band_is_neither_limb_nor_background():
    truth = (250.3, 262.7)
    img, ic = _render(truth, seed=1)
    img[230:250] = 0.0  # 20 missing lines across the disc
    mask = np.ones(img.shape, bool)
    mask[230:250] = False
    m = locate(img, CAM, _hints((246.0, 266.0)), mask=mask)
    assert np.hypot(*np.subtract(m.center_rc, ic.body_center_rc)) < 0.5
    assert m.extras["n_masked"] == 20 * 512


def test_uniform_dark_disc_on_bright_sky_is_unbiased():
    """No crescent: the dark limb alone (3 DN below the sky, 1 DN noise) places the disc to < 0.1 px."""
    img, ic = _render((250.3, 262.7), seed=2, crescent_dn=0.0)
    m = locate(img, CAM, _hints((244.0, 270.0)))
    assert np.hypot(*np.subtract(m.center_rc, ic.body_center_rc)) < 0.1
    assert m.extras["angular_bins"]["bins_lit"] == 0


def test_arc_of_a_body_larger_than_the_frame():
    """26 % of a 330 px Moon's limb in a 400x500 frame, centre outside: measured, not refused."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
    from _scenes import SMALL_CAMERA, scene

    img, truth = scene(7386.0, 30.0, (-40.0, 250.0), sun_angle_deg=-90.0, seed=3)
    assert truth.center_rc[0] < 0  # the centre is outside the frame
    h = Hints(body="moon", range_prior_km=7386.0 * 1.01, sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam))
    m = locate(img, SMALL_CAMERA, h)
    err = np.subtract(m.center_rc, truth.center_rc)
    assert np.hypot(*err) < 0.5 and m.extras["profile"]["model"] == "lunar-lambert"
    sig = np.sqrt([m.covariance["center_r"]["center_r"], m.covariance["center_c"]["center_c"]])
    assert np.all(np.abs(err) < 5 * sig)
    assert m.range_km == pytest.approx(truth.range_km, rel=0.01)


def test_too_big_only_when_no_limb_is_visible():
    from jaxlimb.errors import TooBigError

    rng = np.random.default_rng(0)
    img = 120.0 + rng.normal(0, 2.0, (512, 512))  # the disc fills the frame: no limb in it
    with pytest.raises(TooBigError, match="no limb arc"):
        locate(img, CAM, Hints(body="moon", range_prior_km=20_000.0))


def test_lit_dark_split_puts_the_crescent_bias_in_the_covariance():
    """A crescent brightening toward the limb moves the lit edge ~0.35 px toward the Sun; the dark limb does not.
    The lit/dark split (pipeline.sphere.polarity_split) puts that model error into the centre covariance."""
    img, ic = _render((250.3, 262.7), seed=1)
    m = locate(img, CAM, _hints((244.0, 270.0)))
    split = m.extras["polarity_split"]
    assert split["n_lit"] > 500 and split["n_dark"] > 100
    assert split["delta_rc_px"][0] < -0.2  # lit centre toward -row of the dark one (the crescent is at +row)
    err = np.subtract(m.center_rc, ic.body_center_rc)
    sig_r = math.sqrt(m.covariance["center_r"]["center_r"])
    assert abs(err[0]) > 0.2 and abs(err[0]) < 2.0 * sig_r  # without the split: 0.35 px at sigma 0.05 px
    # the range from the dark limb's own scale (the lit limb's is moved outward by the crescent's profile)
    assert abs(split["dark_a_px"] - ic.semi_axes_px[0]) < 3.0 * split["dark_sigma_a_px"] + 0.05
    assert m.range_km == pytest.approx(300_000.0, rel=0.003)


def test_no_split_without_a_dark_limb():
    img, ic = _render((250.3, 262.7), seed=2, crescent_dn=0.0)
    m = locate(img, CAM, _hints((244.0, 270.0)))
    assert m.extras.get("polarity_split") is None
