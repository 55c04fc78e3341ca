"""Image sizes read from headers (jaxlimb/_image_bounds.py) are the sizes the decoders produce."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from jaxlimb.errors import ImageReadError
from jaxlimb._image_bounds import MAX_IMAGE_PIXELS, HeaderSize, check_size, fits_file_sizes, header_size

ROWS, COLS = 37, 53


@pytest.mark.parametrize(("suffix", "channels", "dtype"), [
    (".png", 1, np.uint8), (".png", 1, np.uint16), (".png", 3, np.uint8), (".tif", 1, np.uint16),
    (".tif", 3, np.uint8), (".jpg", 1, np.uint8), (".jpg", 3, np.uint8), (".jp2", 1, np.uint8), (".bmp", 3, np.uint8),
    (".pgm", 1, np.uint8), (".ppm", 3, np.uint8),
])
def test_header_size_is_the_decoded_size(suffix, channels, dtype, tmp_path):
    rng = np.random.default_rng(3)
    shape = (ROWS, COLS) if channels == 1 else (ROWS, COLS, channels)
    img = rng.integers(0, np.iinfo(dtype).max, shape).astype(dtype)
    p = tmp_path / f"img{suffix}"
    assert cv2.imwrite(str(p), img)
    size = header_size(p)
    decoded = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    assert (size.rows, size.cols) == decoded.shape[:2]
    assert size.channels == (decoded.shape[2] if decoded.ndim == 3 else 1)
    assert size.decoded_bytes >= decoded.nbytes  # never an underestimate


def test_fits_sizes_of_plain_and_tile_compressed_hdus(tmp_path):
    from astropy.io import fits

    p = tmp_path / "two.fits"
    fits.HDUList([fits.PrimaryHDU(np.zeros((ROWS, COLS), np.int16)),
                  fits.CompImageHDU(np.zeros((2 * ROWS, 3 * COLS), np.float32))]).writeto(p)
    sizes = fits_file_sizes(p)
    assert [(s.rows, s.cols, s.sample_bytes) for s in sizes] == [(ROWS, COLS, 2), (2 * ROWS, 3 * COLS, 4)]


def test_non_images_have_no_header_size_and_a_cut_header_is_an_error(tmp_path):
    p = tmp_path / "x.txt"
    p.write_text("hello")
    assert header_size(p) is None
    p.write_bytes(b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0")  # cut inside IHDR
    with pytest.raises(ImageReadError, match="corrupt header"):
        header_size(p)


def test_size_limits(monkeypatch):
    import jaxlimb._validate as validate

    monkeypatch.setattr(validate, "available_memory", lambda: 1e12)
    check_size(HeaderSize(16384, 16384, format="PNG"), "ok.png")  # the largest accepted, when memory allows it
    with pytest.raises(ImageReadError, match="refused before decoding"):
        check_size(HeaderSize(16385, 16384, format="PNG"), "big.png")
    assert MAX_IMAGE_PIXELS == 1 << 28
    with pytest.raises(ImageReadError, match="empty"):
        check_size(HeaderSize(0, 10), "empty.png")
