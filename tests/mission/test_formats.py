"""Mission image formats (VICAR, PDS3, FITS, common) and the validity mask on the shared real frames."""

import numpy as np
import pytest

from jaxlimb._data import shared_data_dir
from jaxlimb.errors import ImageReadError, LabelError
from jaxlimb.imaging.formats import read_frame, validity_mask
from jaxlimb.imaging.io import ColourImageWarning

DATA = shared_data_dir()
CASSINI = DATA / "cassini"


def test_cassini_vicar_frame_reads_with_label_metadata():
    fr = read_frame(CASSINI / "N1511803932_1.IMG")
    assert fr.info.format == "vicar" and fr.data.shape == (1024, 1024) and fr.info.bit_depth == 8
    assert fr.meta.image_time == "2005-331T17:03:10.473Z"  # IMAGE_MID_TIME, not IMAGE_TIME
    assert fr.meta.instrument_id == "ISSNA" and fr.meta.target_name == "ENCELADUS"
    assert fr.meta.exposure_s == pytest.approx(0.26)
    assert fr.n_invalid == 0 and fr.mask_or_none is None
    # the 24-byte line prefix is stripped: no prefix bytes (binary telemetry) in column 0..23
    assert 5 <= fr.data.min() and fr.data.max() <= 255


def test_missing_lines_become_the_mask():
    fr = read_frame(CASSINI / "N1511803965_3.IMG")
    assert fr.meta.missing_lines == 38
    bad_rows = np.flatnonzero(~fr.mask.all(axis=1))
    assert bad_rows.tolist() == list(range(438, 476))  # 38 zero-filled lines
    assert (~fr.mask[438:476]).all()
    # invalid pixels hold the median of the valid ones (no step for code that ignores the mask)
    assert np.all(fr.data[~fr.mask] == np.median(fr.data[fr.mask]))


def test_pds3_detached_label_equals_the_vicar_reading():
    a = read_frame(CASSINI / "N1644787857_1.LBL")
    b = read_frame(CASSINI / "N1644787857_1.IMG")
    assert a.info.format == "pds3" and a.info.bit_depth == 16
    assert np.array_equal(a.data, b.data)
    assert a.meta.target_name == "MIMAS" and a.meta.image_time.startswith("2010-044T20:46:48.392")
    assert b.meta.spacecraft == "CASSINI ORBITER"


@pytest.mark.parametrize("name", ["C1636902_CALIB.IMG", "C2062524_CALIB.IMG", "C2064922_CALIB.IMG"])
def test_voyager_half_frames(name):
    fr = read_frame(DATA / "voyager" / name)
    assert fr.data.shape == (800, 800) and fr.info.dtype == "int16"
    assert fr.data.max() > 1000  # Europa's disc, little-endian HALF read correctly
    assert fr.n_invalid < 0.01 * fr.data.size


def test_fits_nan_corners_are_invalid_and_jp2_header_metadata():
    fr = read_frame(DATA / "sun" / "resampled_hmi.fits")
    assert fr.n_invalid > 0 and np.isfinite(fr.data).all()
    assert np.all(fr.data[~fr.mask] == fr.data[fr.mask].min())  # load_image's fill: dark corners
    assert fr.meta.image_time.startswith("2014-03-01")
    jp2 = read_frame(DATA / "sun" / "2023_01_31__03_39_23_200__SDO_HMI_HMI_continuum.jp2")
    assert jp2.meta.image_time.startswith("2023-01-31T03:39:23")


def test_validity_mask_runs_and_isolated_zeros():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 3, size=(40, 50)).astype(np.uint16)  # sky with many isolated zeros
    a[a == 0] = 1
    a[5, 3] = 0  # isolated zero: valid
    a[10, 10:30] = 0  # lost packet: 20 zeros in a line
    a[20:40, 40:50] = 0  # zero-filled readout window
    m = validity_mask(a)
    assert m[5, 3] and not m[10, 10:30].any() and not m[20:40, 40:50].any()
    assert m.sum() == a.size - 20 - 200


def test_colour_png_becomes_luminance(tmp_path):
    import cv2

    img = np.zeros((32, 32, 3), np.uint8)
    img[..., 2] = 200  # red in OpenCV's BGR order
    cv2.imwrite(str(tmp_path / "c.png"), img)
    with pytest.warns(ColourImageWarning):
        fr = read_frame(tmp_path / "c.png")
    assert fr.data[0, 0] == pytest.approx(0.299 * 200)


def test_corrupt_vicar_label_is_a_typed_error(tmp_path):
    raw = (CASSINI / "N1511803932_1.IMG").read_bytes()
    p = tmp_path / "bad.IMG"
    p.write_bytes(b"LBLSIZE=99999999   " + raw[19:4000])
    with pytest.raises(LabelError):
        read_frame(p)
    with pytest.raises(ImageReadError):
        read_frame(tmp_path / "missing.IMG")


def test_gradient_front_end_ignores_the_edges_of_missing_lines():
    """A zero-filled band across a rendered Moon: with the mask no candidate lies near it."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
    from _scenes import scene

    from jaxlimb.imaging import gradient_front_end

    img, truth = scene(20000.0, 20.0, (200.0, 250.0))
    ref = gradient_front_end(img)  # the same frame without the band
    img = np.array(img, dtype=float)
    img[150:170] = 0.0
    mask = np.ones(img.shape, bool)
    mask[150:170] = False
    cand = gradient_front_end(img, mask=mask)
    assert not np.any((cand.points_rc[:, 0] > 140) & (cand.points_rc[:, 0] < 180))
    blind = gradient_front_end(img)  # the band's edges taken for limb points
    assert np.any((blind.points_rc[:, 0] > 140) & (blind.points_rc[:, 0] < 180))
    assert np.hypot(*np.subtract(cand.center_rc, ref.center_rc)) < 5.0
