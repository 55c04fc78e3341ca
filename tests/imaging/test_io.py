"""Image input and validation (typed errors) and the SDO header truth."""

from __future__ import annotations

import math
import warnings

import cv2
import numpy as np
import pytest
from astropy.io import fits

from jaxlimb._data import shared_data_dir
from jaxlimb.errors import ConfigError, ImageContentError, ImageReadError, LimbInputError
from jaxlimb.imaging import (
    ColourImageWarning,
    load_image,
    read_jp2_header,
    sun_truth_from_header,
    validate_image,
)
from jaxlimb.imaging.sdo import HMI_512_JP2, HMI_512_PNG, hmi_512_truth

SUN = shared_data_dir() / "sun"


def _grad_img(shape=(20, 30), dtype=np.uint8, hi=200):
    r, c = np.mgrid[: shape[0], : shape[1]]
    return ((r * 7 + c * 3) % (hi + 1)).astype(dtype)


@pytest.mark.parametrize("ext, dtype, hi, depth", [(".png", np.uint8, 250, 8), (".png", np.uint16, 60000, 16), (".tif", np.uint16, 60000, 16), (".tiff", np.uint8, 200, 8)])
def test_png_tiff_roundtrip(tmp_path, ext, dtype, hi, depth):
    a = _grad_img((24, 33), dtype, hi)
    p = tmp_path / f"img{ext}"
    assert cv2.imwrite(str(p), a)
    img, info = load_image(p)
    assert img.dtype == np.float64 and img.shape == (24, 33)
    assert np.array_equal(img, a.astype(float))
    assert info.bit_depth == depth and info.max_value == 2**depth - 1
    assert info.format in ("png", "tiff") and info.shape == (24, 33) and not info.was_colour


def test_colour_png_converted_with_warning(tmp_path):
    rgb = np.zeros((16, 16, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 10, 100, 200  # B, G, R in OpenCV order
    rgb[0, 0] = 0
    p = tmp_path / "c.png"
    cv2.imwrite(str(p), rgb)
    with pytest.warns(ColourImageWarning):
        img, info = load_image(p)
    assert issubclass(ColourImageWarning, UserWarning)
    assert info.was_colour
    assert img[5, 5] == pytest.approx(0.299 * 200 + 0.587 * 100 + 0.114 * 10)


def test_fits_first_2d_hdu_with_header(tmp_path):
    data = np.arange(12 * 10, dtype=np.float32).reshape(12, 10)
    data[3, 4] = np.nan
    hdr = fits.Header({"RSUN_OBS": 900.0})
    hdul = fits.HDUList([fits.PrimaryHDU(), fits.ImageHDU(data[None], header=hdr)])
    p = tmp_path / "x.fits"
    hdul.writeto(p)
    img, info = load_image(p)
    assert img.shape == (12, 10) and info.format == "fits" and info.hdu_index == 1
    assert info.header["RSUN_OBS"] == 900.0
    assert info.n_nonfinite_filled == 1 and img[3, 4] == 0.0
    assert info.bit_depth is None


def test_fits_without_image_and_all_nan(tmp_path):
    p = tmp_path / "t.fits"
    fits.HDUList([fits.PrimaryHDU(), fits.BinTableHDU.from_columns([fits.Column("a", "E", array=np.ones(3))])]).writeto(p)
    with pytest.raises(ImageContentError, match="no HDU"):
        load_image(p)
    cube = tmp_path / "cube.fits"
    fits.PrimaryHDU(np.ones((2, 10, 10))).writeto(cube)
    with pytest.raises(ImageContentError, match="2-D"):
        load_image(cube)
    q = tmp_path / "n.fits"
    fits.PrimaryHDU(np.full((10, 10), np.nan)).writeto(q)
    with pytest.raises(ImageContentError, match="finite"):
        load_image(q)


def test_missing_dir_empty_truncated_garbage(tmp_path):
    with pytest.raises(ImageReadError, match="does not exist"):
        load_image(tmp_path / "nope.png")
    with pytest.raises(ImageReadError, match="directory"):
        load_image(tmp_path)
    e = tmp_path / "empty.png"
    e.write_bytes(b"")
    with pytest.raises(ImageReadError, match="empty"):
        load_image(e)
    full = (SUN / HMI_512_PNG).read_bytes()
    t = tmp_path / "trunc.png"
    t.write_bytes(full[: len(full) // 2])
    with pytest.raises(ImageReadError, match="truncated"):
        load_image(t)
    g = tmp_path / "garbage.png"
    g.write_bytes(b"this is not an image at all" * 10)
    with pytest.raises(ImageReadError):
        load_image(g)
    g2 = tmp_path / "garbage.tif"
    g2.write_bytes(b"II*\x00garbage" * 10)
    with pytest.raises(ImageReadError):
        load_image(g2)
    g3 = tmp_path / "garbage.fits"
    g3.write_bytes(b"SIMPLE  = T" + b" " * 100)
    with pytest.raises(ImageReadError):
        load_image(g3)
    assert issubclass(ImageReadError, LimbInputError) and ImageReadError.exit_code == 2


def test_tiny_and_constant_files(tmp_path):
    p = tmp_path / "one.png"
    cv2.imwrite(str(p), np.array([[7]], np.uint8))
    with pytest.raises(ImageContentError, match="at least 8x8"):
        load_image(p)
    q = tmp_path / "const.png"
    cv2.imwrite(str(q), np.full((20, 20), 9, np.uint8))
    with pytest.raises(ImageContentError, match="constant"):
        load_image(q)
    img, _ = load_image(q, reject_constant=False)
    assert img.max() == 9


@pytest.mark.parametrize(
    "arr, msg",
    [
        (np.zeros((0, 0)), "empty"),
        (np.ones((1, 1)), "at least"),
        (np.ones((4, 100)), "at least"),
        (np.ones(100), "2-D"),
        (np.ones((10, 10, 2)), "2-D"),
        (np.ones((3, 10, 10, 1)), "2-D"),
        (np.array([["a"] * 10] * 10), "numeric"),
    ],
)
def test_validate_bad_arrays(arr, msg):
    with pytest.raises(ImageContentError, match=msg):
        validate_image(arr)


def test_validate_nonfinite_and_ok():
    a = np.arange(100.0).reshape(10, 10)
    b = a.copy()
    b[2, 3] = np.nan
    b[4, 4] = np.inf
    with pytest.raises(ImageContentError, match="2 non-finite"):
        validate_image(b)
    out = validate_image(a.astype(np.uint16))
    assert out.dtype == np.float64 and out.flags.c_contiguous and np.array_equal(out, a)
    with pytest.warns(ColourImageWarning):
        g = validate_image(np.stack([a, a, a], -1))
    assert np.allclose(g, a)


def test_sdo_png_and_jp2_read_identically():
    png, ipng = load_image(SUN / HMI_512_PNG)
    jp2, ijp2 = load_image(SUN / HMI_512_JP2)
    assert png.shape == (512, 512) and ipng.bit_depth == 8 and ijp2.format == "jp2"
    assert np.array_equal(png, jp2)
    assert ipng.header is None and ijp2.header is not None


def test_sun_truth_jp2_header_matches_manifest():
    hdr = read_jp2_header(SUN / HMI_512_JP2)
    assert hdr["CRPIX1"] == 256.5 and hdr["RSUN_OBS"] == pytest.approx(973.96844)
    t = sun_truth_from_header(hdr, rows_flipped=True)
    assert t.center_rc == pytest.approx(hmi_512_truth().center_rc, abs=1e-6)
    assert t.radius_px == pytest.approx(202.91, abs=0.005)
    assert t.radius_px == pytest.approx(hmi_512_truth().radius_px, rel=1e-5)
    assert hmi_512_truth().center_rc == (255.5, 255.5)


@pytest.mark.parametrize("name, radius", [("resampled_hmi.fits", 46.90), ("aia_171_level1.fits", 50.66)])
def test_sun_truth_fits(name, radius):
    _, info = load_image(SUN / name)
    t = sun_truth_from_header(info.header)
    assert t.radius_px == pytest.approx(radius, abs=0.01)
    h = info.header
    # the centre moves from the 0-based reference pixel by the rotated CRVAL offset
    th = math.radians(h.get("CROTA2", 0.0))
    dx_w, dy_w = -h["CRVAL1"] / h["CDELT1"], -h["CRVAL2"] / h["CDELT2"]
    dx = math.cos(th) * dx_w + math.sin(th) * dy_w
    dy = -math.sin(th) * dx_w + math.cos(th) * dy_w
    assert t.center_rc[1] == pytest.approx(h["CRPIX1"] - 1 + dx, abs=0.01)
    assert t.center_rc[0] == pytest.approx(h["CRPIX2"] - 1 + dy, abs=0.01)


def test_sun_truth_rotation_and_bad_header():
    base = {
        "CTYPE1": "HPLN-TAN", "CTYPE2": "HPLT-TAN", "CUNIT1": "arcsec", "CUNIT2": "arcsec",
        "CRPIX1": 50.5, "CRPIX2": 40.5, "CDELT1": 2.0, "CDELT2": 2.0, "CRVAL1": 20.0, "CRVAL2": 0.0,
        "CROTA2": 90.0, "RSUN_OBS": 100.0, "NAXIS1": 100, "NAXIS2": 80,
    }
    t = sun_truth_from_header(fits.Header(base))
    # Sun centre is 20" = 10 px west of the reference point; rotated by 90 deg it lies along the pixel y axis
    assert math.hypot(t.center_rc[0] - 39.5, t.center_rc[1] - 49.5) == pytest.approx(10.0, abs=1e-3)
    assert t.center_rc[1] == pytest.approx(49.5, abs=1e-3)
    assert t.radius_px == pytest.approx(50.0, abs=1e-3)
    tf = sun_truth_from_header(fits.Header(base), rows_flipped=True)
    assert tf.center_rc[0] == pytest.approx(79 - t.center_rc[0])
    # ignore_rotation: the unrotated mapping (10 px west along the pixel x axis), the caller's header untouched
    h = fits.Header(base)
    t0 = sun_truth_from_header(h, ignore_rotation=True)
    assert t0.center_rc == pytest.approx((39.5, 39.5), abs=1e-3) and h["CROTA2"] == 90.0
    bad = dict(base)
    del bad["RSUN_OBS"]
    with pytest.raises(ConfigError, match="RSUN_OBS"):
        sun_truth_from_header(bad)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sun_truth_from_header(base)
