"""Checks of both front ends: typed errors, never an invented body."""

from __future__ import annotations

import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.errors import (
    ConfigError,
    ImageContentError,
    NoBodyError,
    RadiusInconsistentError,
    TooBigError,
    TooSmallError,
    TooThinError,
)
from jaxlimb.imaging import Hints, front_end

from ._synth import render_disk

FRONT_ENDS = ["gradient", "scanline"]
_rng = np.random.default_rng(42)
NO_BODY = {
    "all_black": np.zeros((300, 300)),
    "black_read_noise": _rng.normal(5.0, 1.0, (300, 300)),
    "black_quantised": np.round(_rng.normal(3.0, 0.4, (300, 300))),
    "all_white": np.full((300, 300), 255.0),
    "white_saturated_noise": np.clip(_rng.normal(252.0, 3.0, (300, 300)), 0, 255),
    "gaussian_noise": _rng.normal(100.0, 20.0, (300, 300)),
    "uniform_noise": _rng.uniform(0.0, 255.0, (300, 300)),
}


@pytest.mark.parametrize("fe", FRONT_ENDS)
@pytest.mark.parametrize("name", sorted(NO_BODY))
def test_no_body(fe, name):
    with pytest.raises(NoBodyError):
        front_end(fe, NO_BODY[name])


@pytest.mark.parametrize("fe", FRONT_ENDS)
@pytest.mark.parametrize("radius", [1.0, 2.0])
def test_too_small(fe, radius):
    im = render_disk((256, 256), (128.0, 128.0), radius, noise_sigma=2.0)
    with pytest.raises(TooSmallError):
        front_end(fe, im)


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_frame_filling_body_is_too_big(fe):
    im = render_disk((300, 300), (150.0, 150.0), 190.0, noise_sigma=2.0, ss=2)
    with pytest.raises(TooBigError):
        front_end(fe, im)


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_hair_thin_crescent_is_too_thin(fe):
    im = render_disk((300, 300), (150.0, 150.0), 100.0, phase_deg=174.0, noise_sigma=1.0, blur_sigma=1.0, ss=3)
    with pytest.raises(TooThinError):
        front_end(fe, im)


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_thin_crescent_from_hints_is_too_thin(fe):
    im = render_disk((300, 300), (150.0, 150.0), 100.0, phase_deg=120.0, noise_sigma=1.0, blur_sigma=1.0, ss=3)
    h = Hints(expected_radius_px=100.0, sun_dir_camera=(0.0, 0.0005, 1.0))  # Sun behind the body: new moon
    with pytest.raises(TooThinError):
        front_end(fe, im, hints=h)


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_radius_inconsistent_with_prior(fe):
    im = render_disk((400, 400), (200.0, 200.0), 150.0, blur_sigma=1.0, noise_sigma=2.0, ss=3)
    h = Hints(expected_radius_px=60.0, expected_radius_uncertainty_frac=0.05)
    with pytest.raises(RadiusInconsistentError, match="outside"):
        front_end(fe, im, hints=h)


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_bad_arrays(fe):
    a = np.ones((50, 50))
    a[3, 3] = np.nan
    with pytest.raises(ImageContentError):
        front_end(fe, a)
    with pytest.raises(ImageContentError):
        front_end(fe, np.ones((1, 1)))


def test_unknown_front_end_and_mismatched_options():
    from jaxlimb.imaging import GradientOptions

    with pytest.raises(ConfigError, match="front_end"):
        front_end("canny", np.zeros((10, 10)))
    with pytest.raises(ConfigError, match="ScanlineOptions"):
        front_end("scanline", np.zeros((10, 10)), options=GradientOptions())
    with pytest.raises(ConfigError, match="expected_radius_px"):
        front_end("gradient", np.zeros((10, 10)), hints={"expected_radius_px": -3})


@pytest.mark.parametrize("fe", FRONT_ENDS)
@pytest.mark.parametrize(
    "center, radius, sun, phase",
    [((150.0, 300.0), 240.0, (-0.59, 0.81), 63.0), ((380.0, 200.0), 150.0, (1.0, 0.0), 80.0), ((200.0, -100.0), 180.0, (0.0, -1.0), 40.0)],
)
def test_lit_limb_outside_frame_is_not_invented(fe, center, radius, sun, phase):
    """Only the terminator (and frame edges) are visible: a typed check failure, never a terminator circle."""
    from jaxlimb.errors import CheckFailed

    im = render_disk((400, 400), center, radius, phase_deg=phase, sun_dir_rc=sun, blur_sigma=1.0, noise_sigma=2.0, ss=2)
    with pytest.raises(CheckFailed):
        front_end(fe, im)


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_aia_corona_is_handled(fe):
    """AIA 171 A: the corona blurs the limb.  Either a typed check failure or a circle near the truth."""

    from jaxlimb.errors import CheckFailed
    from jaxlimb.imaging import load_image, sun_truth_from_header

    img, info = load_image(shared_data_dir() / "sun/aia_171_level1.fits")
    t = sun_truth_from_header(info.header)
    try:
        lc = front_end(fe, img)
    except CheckFailed:
        return
    assert np.hypot(lc.center_rc[0] - t.center_rc[0], lc.center_rc[1] - t.center_rc[1]) < 3.5
    assert abs(lc.radius - t.radius_px) < 3.5


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_16bit_png_end_to_end(fe, tmp_path):
    import cv2

    from jaxlimb.imaging import load_image

    im = render_disk((360, 420), (170.3, 215.8), 120.0, phase_deg=50.0, sun_dir_rc=(0.0, 1.0), amplitude=30000.0,
                     background=300.0, blur_sigma=1.0, noise_sigma=40.0, quantize_bits=16, ss=3)
    p = tmp_path / "moon16.png"
    assert cv2.imwrite(str(p), im.astype(np.uint16))
    img, info = load_image(p)
    assert info.bit_depth == 16
    lc = front_end(fe, img)
    assert np.hypot(lc.center_rc[0] - 170.3, lc.center_rc[1] - 215.8) < 1.0
    assert abs(lc.radius - 120.0) < 1.0
    assert lc.lit_direction is not None and lc.lit_direction[1] > 0.95


@pytest.mark.parametrize("fe", FRONT_ENDS)
def test_large_quantised_black_frame_has_no_body(fe):
    """A 1944x2592 8-bit dark frame (read noise 0.4 DN, quantised): block averaging must not round."""
    rng = np.random.default_rng(7)
    im = np.clip(np.round(rng.normal(3.0, 0.4, (1944, 2592))), 0, 255).astype(np.uint8)
    with pytest.raises(NoBodyError):
        front_end(fe, im)
