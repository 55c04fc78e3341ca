"""Image input and validation.

:func:`load_image` reads 8/16-bit PNG and TIFF (OpenCV, ``cv2.IMREAD_UNCHANGED``),
FITS (astropy; first HDU holding a 2-D array) and JPEG 2000 (OpenCV, which ships
OpenJPEG; glymur as a fallback) and returns a float64 ``[row, col]`` array plus an
:class:`ImageInfo`.  :func:`validate_image` applies the same checks to in-memory
arrays.  Every failure raises a typed error of :mod:`jaxlimb.errors`:

* :class:`~jaxlimb.errors.ImageReadError` -- missing file, directory, empty file,
  unknown/corrupt/truncated content;
* :class:`~jaxlimb.errors.ImageContentError` -- wrong dimensionality, empty array,
  smaller than ``min_size`` x ``min_size``, non-finite values, constant image.

Colour images are converted to grey with the ITU-R BT.601 weights
(0.299 R + 0.587 G + 0.114 B, the weights of ``cv2.COLOR_BGR2GRAY``) and a
:class:`ColourImageWarning` is issued.

Orientation: the array is returned exactly as stored (row 0 = first stored row).
For FITS this means row 0 is FITS ``y = 1`` (the bottom of the usual display);
all truth derived from FITS headers (:func:`jaxlimb.imaging.sdo.sun_truth_from_header`)
uses the same array indices, so no flip is ever needed.

Decision (FITS missing data): FITS files mark missing pixels with NaN (e.g. the
off-disk corners of SDO images).  For FITS only, non-finite pixels are replaced
by the minimum finite value and counted in ``ImageInfo.n_nonfinite_filled``; in
every other format, and in :func:`validate_image`, a non-finite value is an
:class:`~jaxlimb.errors.ImageContentError`.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..errors import ImageContentError, ImageReadError

#: Smallest accepted image side (pixels).  Smaller images cannot hold a limb that
#: the 9-tap gradient kernel or the 8-pixel scan-line mask could measure.
MIN_IMAGE_SIZE = 8

_FITS_SUFFIXES = (".fits", ".fit", ".fts", ".fits.gz", ".fit.gz", ".fts.gz")
_JP2_SUFFIXES = (".jp2", ".j2k", ".jpx", ".jpf", ".j2c")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_IEND = b"IEND\xaeB`\x82"


class ColourImageWarning(UserWarning):
    """A colour image was converted to grey (BT.601 luma)."""


@dataclass(frozen=True)
class ImageInfo:
    """Where an image came from and how it was converted.

    Attributes
    ----------
    bit_depth
        Bits per sample of the stored integer data (8, 16, 32), or ``None`` for
        floating-point data (FITS ``BITPIX < 0``, float TIFF, float arrays).
    source
        The file path as a string, or ``"<array>"`` for in-memory arrays.
    format
        ``"png"``, ``"tiff"``, ``"fits"``, ``"jp2"``, ``"other"`` (any other format
        OpenCV decodes) or ``"array"``.
    shape
        ``(rows, cols)`` of the returned grey image.
    dtype
        NumPy dtype name of the stored data before conversion to float64.
    was_colour
        True when the stored image had 3 or 4 channels and was converted to grey.
    max_value
        Largest representable value (``2**bit_depth - 1``) or ``None`` for floats.
    header
        The FITS header (``astropy.io.fits.Header``) of the HDU read, or the
        FITS-like header of a JPEG 2000 XML box (also a ``Header``); else ``None``.
    hdu_index
        Index of the FITS HDU read (``None`` for other formats).
    n_nonfinite_filled
        FITS only: number of NaN/inf pixels replaced by the minimum finite value.
    """

    bit_depth: int | None
    source: str
    format: str
    shape: tuple[int, int]
    dtype: str
    was_colour: bool = False
    max_value: float | None = None
    header: Any = field(default=None, repr=False, compare=False)
    hdu_index: int | None = None
    n_nonfinite_filled: int = 0


# ----------------------------------------------------------------------------- helpers
def _bit_depth(dtype: np.dtype) -> int | None:
    if np.issubdtype(dtype, np.integer):
        return int(np.dtype(dtype).itemsize * 8)
    if dtype == np.bool_:
        return 1
    return None


def _to_grey(a: np.ndarray, order: str, source: str) -> np.ndarray:
    """Convert ``(rows, cols, 3|4)`` colour data to float64 grey with a warning."""
    a = np.asarray(a, dtype=np.float64)[..., :3]
    if order == "bgr":
        b, g, r = a[..., 0], a[..., 1], a[..., 2]
    else:
        r, g, b = a[..., 0], a[..., 1], a[..., 2]
    warnings.warn(
        f"{source}: colour image with {a.shape[-1]} channels converted to grey "
        "(0.299 R + 0.587 G + 0.114 B)",
        ColourImageWarning,
        stacklevel=3,
    )
    return 0.299 * r + 0.587 * g + 0.114 * b


def validate_image(
    image: Any,
    *,
    name: str = "image",
    min_size: int = MIN_IMAGE_SIZE,
    reject_constant: bool = True,
    colour_order: str = "rgb",
    as_float64: bool = True,
) -> np.ndarray:
    """Check an in-memory image and return it as a C-contiguous float64 ``[row, col]`` array.

    Parameters
    ----------
    image
        Array-like, 2-D ``(rows, cols)``; ``(rows, cols, 1)`` is squeezed and
        ``(rows, cols, 3|4)`` colour is converted to grey with a
        :class:`ColourImageWarning`.
    name
        Name used in error messages.
    min_size
        Smallest accepted number of rows and of columns (default 8).
    reject_constant
        Raise :class:`~jaxlimb.errors.ImageContentError` for a constant image.  The
        front ends pass ``False`` and raise :class:`~jaxlimb.errors.NoBodyError`
        instead (an all-black frame is a valid frame without a body).
    colour_order
        Channel order of 3/4-channel input, ``"rgb"`` (default) or ``"bgr"``.
    as_float64
        Return float64 (default).  ``False`` returns grey integer/float data
        unconverted (no copy of a 5-Mpixel frame; the front ends convert only their
        region of interest).

    Raises
    ------
    ImageContentError
        Non-numeric data, wrong dimensionality, empty, smaller than ``min_size``,
        NaN/inf values, or (``reject_constant``) a constant image.
    """
    a = _grey_array(image, name, colour_order)
    if a.ndim != 2:
        raise ImageContentError(
            f"{name} must be 2-D [row, col] (or colour [row, col, 3|4]), got shape {a.shape}"
        )
    if a.size == 0:
        raise ImageContentError(f"{name} is empty (shape {a.shape})")
    if a.shape[0] < min_size or a.shape[1] < min_size:
        raise ImageContentError(
            f"{name} must be at least {min_size}x{min_size} pixels, got {a.shape[0]}x{a.shape[1]}"
        )
    out = np.ascontiguousarray(a, dtype=np.float64) if as_float64 else np.ascontiguousarray(a)
    if np.issubdtype(out.dtype, np.floating):
        finite = np.isfinite(out)
        if not finite.all():
            n = int(out.size - np.count_nonzero(finite))
            raise ImageContentError(f"{name} has {n} non-finite (NaN/inf) pixel(s); all pixels must be finite")
    if reject_constant and float(out.max()) == float(out.min()):
        raise ImageContentError(f"{name} is constant (every pixel = {float(out.min())!r}); no limb to find")
    return out


def _grey_array(image: Any, name: str, colour_order: str) -> np.ndarray:
    """``image`` as a numeric array (booleans as ``uint8``), a single channel squeezed and colour converted to
    grey; its dimensionality is not checked."""
    try:
        a = np.asarray(image)
    except Exception as e:  # pragma: no cover - exotic array-likes
        raise ImageContentError(f"{name} cannot be converted to an array: {e}") from None
    if a.dtype == np.bool_:
        a = a.astype(np.uint8)
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
        raise ImageContentError(f"{name} must be a numeric array (integer or float), got dtype {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 3 and a.shape[2] in (3, 4) and a.shape[0] > 4:
        if colour_order not in ("rgb", "bgr"):
            raise ImageContentError(f"colour_order must be 'rgb' or 'bgr', got {colour_order!r}")
        a = _to_grey(a, colour_order, name)
    return a


# ----------------------------------------------------------------------------- readers
def _suffix(p: Path) -> str:
    name = p.name.lower()
    for s in _FITS_SUFFIXES + _JP2_SUFFIXES:
        if name.endswith(s):
            return s
    return p.suffix.lower()


def read_fits(p: Path) -> tuple[np.ndarray, Any, int]:
    """The image array of a FITS file (the first HDU with 2-D data), its header and the HDU's index; astropy
    reads it (imported here: an optional, heavy dependency)."""
    from astropy.io import fits

    from .._image_bounds import check_size, fits_size

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with fits.open(p, memmap=False) as hdul:
                for i, hdu in enumerate(hdul):
                    check_size(fits_size(hdu.header, p), p)  # before its data are read or decompressed
                    data = getattr(hdu, "data", None)
                    if data is None or not isinstance(data, np.ndarray) or data.dtype.names is not None:
                        continue
                    d = np.squeeze(np.asarray(data))
                    if d.ndim == 2:
                        return np.array(d), hdu.header.copy(), i
                raise ImageContentError(f"FITS file {str(p)!r} has no HDU holding a 2-D image")
    except (ImageContentError, ImageReadError):
        raise
    except Exception as e:  # astropy raises OSError/ValueError/TypeError on corrupt files
        raise ImageReadError(f"cannot read FITS file {str(p)!r}: {type(e).__name__}: {e}") from None


def read_jp2_header(path: str | os.PathLike[str]) -> Any:
    """Return the FITS-like header stored in a JPEG 2000 XML box as an ``astropy.io.fits.Header``.

    Helioviewer/SDO JPEG 2000 files carry ``<meta><fits><KEY>value</KEY>...``.
    Values are converted to int/float where possible.  Returns ``None`` when the
    file has no such box.
    """
    import re

    from astropy.io import fits

    raw = Path(path).read_bytes()
    m = re.search(rb"<fits>(.*?)</fits>", raw, re.S)
    if m is None:
        return None
    hdr = fits.Header()
    for key, val in re.findall(rb"<([A-Za-z0-9_\-]+)>([^<]*)</\1>", m.group(1)):
        k = key.decode("ascii", "replace").upper()
        v_s = val.decode("utf-8", "replace").strip()
        v: Any = v_s
        for conv in (int, float):
            try:
                v = conv(v_s)
                break
            except ValueError:
                continue
        if len(k) > 8 or k in ("COMMENT", "HISTORY"):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                hdr[k] = v
            except (ValueError, TypeError):
                continue
    return hdr


def _read_cv2(p: Path, kind: str) -> np.ndarray:
    from .._image_bounds import check_size, header_size

    check_size(header_size(p), p)  # the declared size, before the decoder allocates it
    if kind == "png":
        with open(p, "rb") as fh:
            head = fh.read(8)
            fh.seek(max(0, p.stat().st_size - 8))
            tail = fh.read(8)
        if head != _PNG_SIGNATURE:
            raise ImageReadError(f"{str(p)!r} is not a PNG file (bad signature)")
        if tail != _PNG_IEND:
            raise ImageReadError(f"PNG file {str(p)!r} is truncated (no IEND chunk at the end)")
    buf = np.fromfile(p, dtype=np.uint8)
    try:
        img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    except cv2.error as e:  # OpenCV's own size limit (OPENCV_IO_MAX_IMAGE_PIXELS) or a decoder assertion
        msg = " ".join(str(e).split())[-160:]
        raise ImageReadError(f"cannot decode image file {str(p)!r}: {msg}") from None
    if img is None and kind == "jp2":
        try:  # pragma: no cover - only when OpenCV lacks OpenJPEG
            import glymur

            img = np.asarray(glymur.Jp2k(str(p))[:])
        except Exception as e:  # pragma: no cover
            raise ImageReadError(f"cannot decode JPEG 2000 file {str(p)!r}: {e}") from None
    if img is None:
        raise ImageReadError(f"cannot decode image file {str(p)!r} (corrupt, truncated or unsupported format)")
    return img


def load_image(
    path: str | os.PathLike[str],
    *,
    min_size: int = MIN_IMAGE_SIZE,
    reject_constant: bool = True,
) -> tuple[np.ndarray, ImageInfo]:
    """Read an image file as a float64 ``[row, col]`` array.

    Parameters
    ----------
    path
        PNG/TIFF (8 or 16 bit, grey or colour), FITS (first 2-D HDU), JPEG 2000, or
        any other format OpenCV decodes.
    min_size, reject_constant
        As in :func:`validate_image`.

    Returns
    -------
    image : numpy.ndarray
        float64, shape ``(rows, cols)``, values in the stored units (DN).
    info : ImageInfo
        Bit depth, format, FITS/JP2 header, ...

    Raises
    ------
    ImageReadError
        Missing path, a directory, an empty file, an undecodable/truncated file.
    ImageContentError
        See :func:`validate_image`.
    """
    p = Path(path)
    _check_readable_file(p)
    fmt, raw, a, header, hdu_index, n_filled = _read_raw(p)
    was_colour = a.ndim == 3 and a.shape[2] in (3, 4)
    img = validate_image(
        a,
        name=f"image {str(p)!r}",
        min_size=min_size,
        reject_constant=reject_constant,
        colour_order="rgb" if fmt == "fits" else "bgr",
    )
    bd = _bit_depth(raw.dtype)
    info = ImageInfo(
        bit_depth=bd,
        source=str(p),
        format=fmt,
        shape=(int(img.shape[0]), int(img.shape[1])),
        dtype=str(raw.dtype),
        was_colour=bool(was_colour),
        max_value=float(2**bd - 1) if bd else None,
        header=header,
        hdu_index=hdu_index,
        n_nonfinite_filled=n_filled,
    )
    return img, info


def _read_raw(p: Path) -> tuple[str, np.ndarray, np.ndarray, Any, int | None, int]:
    """The file's format, stored array, the array to validate (FITS: float, non-finite pixels filled), header,
    FITS HDU index and number of filled pixels."""
    suf = _suffix(p)
    header = None
    hdu_index = None
    n_filled = 0
    if suf in _FITS_SUFFIXES:
        fmt = "fits"
        raw, header, hdu_index = read_fits(p)
        raw, a, n_filled = _fits_as_float(raw, p)
    else:
        fmt = {".png": "png", ".tif": "tiff", ".tiff": "tiff"}.get(suf, "jp2" if suf in _JP2_SUFFIXES else "other")
        raw = _read_cv2(p, fmt)
        if fmt == "jp2":
            header = read_jp2_header(p)
        a = raw
    return fmt, raw, a, header, hdu_index, n_filled


def _check_readable_file(p: Path) -> None:
    """:class:`ImageReadError` for a missing path, a directory, an empty or unreadable file."""
    if not p.exists():
        raise ImageReadError(f"image file {str(p)!r} does not exist")
    if p.is_dir():
        raise ImageReadError(f"image path {str(p)!r} is a directory, not a file")
    try:
        size = p.stat().st_size
    except OSError as e:  # pragma: no cover
        raise ImageReadError(f"cannot stat image file {str(p)!r}: {e}") from None
    if size == 0:
        raise ImageReadError(f"image file {str(p)!r} is empty (0 bytes)")
    if not os.access(p, os.R_OK):
        raise ImageReadError(f"image file {str(p)!r} is not readable (permission denied)")


def _fits_as_float(raw: np.ndarray, p: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """A FITS array in native byte order, as float64 with its non-finite pixels set to the minimum, and the
    number of pixels set."""
    if raw.dtype.byteorder not in ("=", "|"):
        raw = raw.astype(raw.dtype.newbyteorder("="))
    a = raw.astype(np.float64)
    finite = np.isfinite(a)
    if not finite.any():
        raise ImageContentError(f"FITS image {str(p)!r} has no finite pixel")
    n_filled = int(a.size - np.count_nonzero(finite))
    if n_filled:
        a[~finite] = a[finite].min()
    return raw, a, n_filled


__all__ = [
    "MIN_IMAGE_SIZE",
    "ColourImageWarning",
    "ImageInfo",
    "load_image",
    "read_jp2_header",
    "validate_image",
]
