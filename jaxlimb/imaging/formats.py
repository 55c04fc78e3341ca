"""Mission image formats: VICAR, PDS3, PDS4, FITS and the common ones, with a validity mask.

:func:`read_frame` reads any file jaxlimb accepts and returns a :class:`Frame`: the image
as float64 ``[row, col]`` (DN), a validity mask (``True`` = a measured pixel) and the label
metadata a navigation chain needs (image time, spacecraft, instrument, target).

Readers (maintained ones, no hand-written parser):

* **VICAR** (a file whose first bytes are ``LBLSIZE=``): ``rms-vicar``
  (:class:`vicar.VicarImage`), which strips the binary line prefixes (Cassini ISS EDR:
  24 bytes per line) and honours ``INTFMT``/``REALFMT`` byte order.  When a PDS3 label
  (``.LBL``) lies beside it, its keywords are merged in (the PDS3 label wins).
* **PDS3** (a label starting with ``PDS_VERSION_ID``, attached or detached) and **PDS4**
  (an XML label): ``pdr`` (:func:`pdr.read`), the first 2-D ``IMAGE``-like object.
* **FITS**, PNG, TIFF, JPEG (colour to luminance), JPEG 2000: :func:`jaxlimb.imaging.io.load_image`;
  the FITS header gives the metadata (``DATE-OBS``, ``TELESCOP``, ``INSTRUME``, ``OBJECT``).

Validity mask (decision): data that were never measured are stored as a fill value (0 in
Cassini and Voyager products): missing lines (``MISSING_LINES`` in the label), lost packets
(a zero run inside a line) and zero-filled readout windows.  A pixel is invalid when it
equals the fill value and lies in a horizontal *or* vertical run of at least
``min_run`` (default 8) fill pixels.  A run of 8 exact zeros has a probability below
``1e-8`` per pixel for any image with noise of 1 DN or more, so real sky at 0 DN keeps its
isolated zeros while every missing line, packet and window is caught.  FITS NaNs (off-disc
corners of SDO frames) are invalid too.  Masked pixels are filled with the median of the
valid pixels in ``Frame.data`` (so that no code that ignores the mask sees a step; FITS NaNs
keep :func:`~jaxlimb.imaging.io.load_image`'s minimum-value fill), and the
front ends and the annulus selection drop them (:func:`jaxlimb.imaging.masking.mask_gradient`).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ImageContentError, ImageReadError, LabelError
from .io import MIN_IMAGE_SIZE, ImageInfo, read_fits, load_image, validate_image

#: Shortest run of fill-value pixels (along a row or a column) taken as missing data.
MIN_FILL_RUN = 8

_VICAR_MAGIC = b"LBLSIZE="
_PDS3_MAGIC = b"PDS_VERSION_ID"


@dataclass(frozen=True)
class FrameMeta:
    """Label metadata of a frame (``None`` where the label does not say).

    Attributes
    ----------
    image_time
        UTC of mid-exposure as in the label (``IMAGE_MID_TIME``, else ``IMAGE_TIME``
        corrected by half the exposure when both are given, else ``START_TIME``,
        FITS ``DATE-OBS``), an ISO/DOY string SPICE's ``str2et`` reads.
    spacecraft
        ``SPACECRAFT_NAME``/``INSTRUMENT_HOST_NAME`` (FITS ``TELESCOP``), e.g. ``"CASSINI ORBITER"``.
    instrument_id
        ``INSTRUMENT_ID`` (FITS ``INSTRUME``), e.g. ``"ISSNA"``.
    target_name
        ``TARGET_NAME`` (FITS ``OBJECT``), e.g. ``"ENCELADUS"``.
    exposure_s
        Exposure duration (s).
    missing_lines
        ``MISSING_LINES`` of the label, if any.
    label
        The whole label as a flat ``{KEY: value}`` dict (strings, numbers, tuples).
    """

    image_time: str | None = None
    spacecraft: str | None = None
    instrument_id: str | None = None
    target_name: str | None = None
    exposure_s: float | None = None
    missing_lines: int | None = None
    label: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)


@dataclass(frozen=True)
class Frame:
    """An image with its validity mask and label metadata.

    Attributes
    ----------
    data
        float64 ``[row, col]`` in DN; invalid pixels hold the median of the valid ones.
    mask
        bool ``[row, col]``, ``True`` = valid (measured) pixel.
    info
        :class:`~jaxlimb.imaging.io.ImageInfo` (format, bit depth, FITS header, ...).
    meta
        :class:`FrameMeta` from the label.
    """

    data: np.ndarray
    mask: np.ndarray
    info: ImageInfo
    meta: FrameMeta

    @property
    def n_invalid(self) -> int:
        """Number of masked (never measured) pixels."""
        return int(self.mask.size - np.count_nonzero(self.mask))

    @property
    def mask_or_none(self) -> np.ndarray | None:
        """The mask, or ``None`` when every pixel is valid (lets callers skip the masking work)."""
        return None if self.n_invalid == 0 else self.mask


# ----------------------------------------------------------------------------- mask
def _runs_1d(fill: np.ndarray, min_run: int) -> np.ndarray:
    """Cells of ``fill`` (2-D bool) in runs of >= ``min_run`` along axis 1."""
    rows, cols = fill.shape
    pad = np.zeros((rows, 1), dtype=np.int8)
    d = np.diff(np.concatenate([pad, fill.astype(np.int8), pad], axis=1), axis=1)
    out = np.zeros_like(fill)
    for r in np.flatnonzero(fill.any(axis=1)):
        starts = np.flatnonzero(d[r] == 1)
        ends = np.flatnonzero(d[r] == -1)
        for s, e in zip(starts, ends):
            if e - s >= min_run:
                out[r, s:e] = True
    return out


def validity_mask(data: np.ndarray, fill_value: float = 0.0, min_run: int = MIN_FILL_RUN) -> np.ndarray:
    """``True`` where a pixel was measured: not a fill value in a run of ``min_run`` along a row or column.

    Parameters
    ----------
    data
        2-D image (any numeric dtype); non-finite pixels are always invalid.
    fill_value
        The value missing data are stored as (0 in VICAR/PDS EDRs).
    min_run
        Shortest horizontal or vertical run of fill pixels taken as missing (default 8).
    """
    a = np.asarray(data)
    bad = ~np.isfinite(a) if np.issubdtype(a.dtype, np.floating) else np.zeros(a.shape, bool)
    fill = a == fill_value
    if fill.any():
        bad |= _runs_1d(fill, min_run) | _runs_1d(fill.T, min_run).T
    return ~bad


def _fill_invalid(a: np.ndarray, mask: np.ndarray) -> np.ndarray:
    if mask.all():
        return a
    out = a.copy()
    out[~mask] = float(np.median(a[mask]))
    return out


# ----------------------------------------------------------------------------- labels
def _flat_label(items) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in items:
        if isinstance(k, str) and k not in out:
            out[k.upper()] = v
    return out


def _num_or_none(v: Any) -> float | None:
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _str_or_none(v: Any) -> str | None:
    if v is None:
        return None
    s = str(v).strip().strip('"').strip()
    return s or None


def meta_from_label(label: dict[str, Any]) -> FrameMeta:
    """:class:`FrameMeta` from a flat PDS3/VICAR/FITS keyword dict (see the attribute docs for the keys)."""
    g = label.get
    exp = _num_or_none(g("EXPOSURE_DURATION"))
    exposure_s = exp / 1000.0 if exp is not None else _num_or_none(g("EXPTIME"))  # PDS/VICAR: ms; FITS: s
    time = _str_or_none(g("IMAGE_MID_TIME")) or _str_or_none(g("IMAGE_TIME")) or _str_or_none(g("START_TIME"))
    if time is None:
        time = _str_or_none(g("DATE-OBS")) or _str_or_none(g("DATE_OBS"))
    ml = _num_or_none(g("MISSING_LINES"))
    return FrameMeta(
        image_time=time,
        spacecraft=_str_or_none(g("SPACECRAFT_NAME") or g("INSTRUMENT_HOST_NAME") or g("TELESCOP")),
        instrument_id=_str_or_none(g("INSTRUMENT_ID") or g("INSTRUME")),
        target_name=_str_or_none(g("TARGET_NAME") or g("OBJECT")),
        exposure_s=exposure_s,
        missing_lines=int(ml) if ml is not None else None,
        label=label,
    )


# ----------------------------------------------------------------------------- readers
def _head(p: Path, n: int = 64) -> bytes:
    with open(p, "rb") as fh:
        return fh.read(n)


def _read_vicar(p: Path) -> tuple[np.ndarray, dict[str, Any]]:
    from .._image_bounds import check_size, vicar_size

    check_size(vicar_size(p), p)  # the label's size against the file and memory, before reading the data
    import vicar

    try:
        im = vicar.VicarImage(str(p))
        a = np.asarray(im.data_2d)
        label = _flat_label(im.label.items())
    except Exception as e:  # rms-vicar raises VicarError/ValueError/IndexError on a corrupt label
        raise LabelError(f"cannot read VICAR file {str(p)!r}: {type(e).__name__}: {e}") from None
    for lbl in (p.with_suffix(".LBL"), p.with_suffix(".lbl")):
        if lbl.is_file():
            label.update(_pds_label(_pdr_read(lbl)))
            break
    return a, label


def _pdr_read(p: Path):
    import pdr

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return pdr.read(str(p))
    except Exception as e:  # pdr raises many types on a corrupt or unsupported label
        raise LabelError(f"cannot read PDS label {str(p)!r}: {type(e).__name__}: {e}") from None


def _pds_label(d) -> dict[str, Any]:
    try:
        items = [(k, d.metaget(k)) for k in _META_KEYS]
    except Exception:  # pragma: no cover - a label pdr parsed but cannot query
        return {}
    return {k: v for k, v in items if v is not None}


_META_KEYS = ("IMAGE_MID_TIME", "IMAGE_TIME", "START_TIME", "SPACECRAFT_NAME", "INSTRUMENT_HOST_NAME",
              "INSTRUMENT_ID", "TARGET_NAME", "EXPOSURE_DURATION", "MISSING_LINES", "start_date_time",
              "DATE-OBS")


def _pds3_image(d, p: Path) -> None:  # noqa: ANN001
    """A PDS3 label's layout against its data file, before any data are read: the file holds exactly
    ``FILE_RECORDS`` x ``RECORD_BYTES`` (fixed-length records), the ``IMAGE`` object ends inside the file,
    and its size passes :func:`jaxlimb._image_bounds.check_size`; else :class:`~jaxlimb.errors.LabelError`."""
    from .._image_bounds import HeaderSize, check_size

    def num(v: Any) -> int | None:
        try:
            return int(v)
        except (TypeError, ValueError):
            return None

    img = d.metaget("IMAGE")
    if img is None or not hasattr(img, "get"):
        return
    lines, samples = num(img.get("LINES")), num(img.get("LINE_SAMPLES"))
    bits, bands = num(img.get("SAMPLE_BITS")) or 8, num(img.get("BANDS")) or 1
    if lines is None or samples is None:
        return
    size = HeaderSize(lines, samples, bands, max(1, bits // 8), "PDS3")
    check_size(size, p)
    pointer = d.metaget("^IMAGE")
    name, record = (pointer if isinstance(pointer, (tuple, list)) and len(pointer) == 2 else
                    (pointer, 1) if isinstance(pointer, str) else (None, pointer))
    data_file = p if name is None else next((f for f in p.parent.iterdir() if f.name.lower() == str(name).lower()), None)
    record_bytes, file_records = num(d.metaget("RECORD_BYTES")), num(d.metaget("FILE_RECORDS"))
    if data_file is None or record_bytes is None or num(record) is None:
        return  # pdr reports a missing data file itself
    have = data_file.stat().st_size
    if str(d.metaget("RECORD_TYPE") or "").upper() == "FIXED_LENGTH" and file_records is not None \
            and file_records * record_bytes != have:
        raise LabelError(f"PDS3 label {str(p)!r}: FILE_RECORDS x RECORD_BYTES = {file_records} x {record_bytes} = "
                         f"{file_records * record_bytes} bytes, but {data_file.name!r} holds {have}: a wrong "
                         "RECORD_BYTES/FILE_RECORDS or a truncated file")
    line = (num(img.get("LINE_PREFIX_BYTES")) or 0) + (num(img.get("LINE_SUFFIX_BYTES")) or 0) + samples * bits // 8
    end = (num(record) - 1) * record_bytes + lines * bands * line  # type: ignore[operator]
    if end > have:
        raise LabelError(f"PDS3 label {str(p)!r}: the IMAGE object (record {record} of {record_bytes} bytes, "
                         f"{lines} x {samples} x {bits} bits) ends at byte {end}, past the end of "
                         f"{data_file.name!r} ({have} bytes): a wrong RECORD_BYTES or a truncated file")


def _read_pds(p: Path) -> tuple[np.ndarray, dict[str, Any]]:
    d = _pdr_read(p)
    if p.suffix.lower() != ".xml":
        _pds3_image(d, p)
    image = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for key in d.keys():
            if "IMAGE" not in key.upper() or "HEADER" in key.upper():
                continue
            try:
                obj = np.asarray(d[key])
            except Exception:  # an object pdr cannot load: try the next one
                continue
            if obj.dtype.names is None and np.squeeze(obj).ndim == 2:
                image = np.squeeze(obj)
                break
    if image is None:
        raise ImageReadError(f"PDS label {str(p)!r} points to no readable 2-D image (objects: {list(d.keys())})")
    label = _pds_label(d)
    if "START_TIME" not in label and "start_date_time" in label:  # PDS4 Time_Coordinates
        label["START_TIME"] = label["start_date_time"]
    return image, label


def _native(a: np.ndarray) -> np.ndarray:
    if a.dtype.byteorder not in ("=", "|"):
        a = a.astype(a.dtype.newbyteorder("="))
    return a


def _frame_from_array(p: Path, raw: np.ndarray, label: dict[str, Any], fmt: str, min_size: int) -> Frame:
    raw = _native(np.asarray(raw))
    mask = validity_mask(raw)
    if not mask.any():
        raise ImageContentError(f"image {str(p)!r} holds no measured pixel (every pixel is fill)")
    a = validate_image(np.where(mask, raw, 0), name=f"image {str(p)!r}", min_size=min_size, reject_constant=False)
    a = _fill_invalid(a, mask)
    bd = int(raw.dtype.itemsize * 8) if np.issubdtype(raw.dtype, np.integer) else None
    info = ImageInfo(bit_depth=bd, source=str(p), format=fmt, shape=(int(a.shape[0]), int(a.shape[1])),
                     dtype=str(raw.dtype), max_value=float(2**bd - 1) if bd else None)
    return Frame(a, mask, info, meta_from_label(label))


def _fits_label(header) -> dict[str, Any]:
    return {str(k).upper(): v for k, v in header.items() if k} if header is not None else {}


def _frame_from_file(p: Path, min_size: int) -> Frame:
    a, info = load_image(p, min_size=min_size, reject_constant=False)
    mask = np.ones(a.shape, dtype=bool)
    if info.format == "fits" and info.n_nonfinite_filled:
        # load_image already filled the NaNs with the minimum finite value (SDO: the dark off-disc corners)
        raw, _, _ = read_fits(p)
        mask = np.isfinite(np.asarray(raw, dtype=np.float64))
    return Frame(a, mask, info, meta_from_label(_fits_label(info.header)))


def read_frame(path: str | os.PathLike[str], *, min_size: int = MIN_IMAGE_SIZE) -> Frame:
    """Read an image file of any supported format as a :class:`Frame`.

    Parameters
    ----------
    path
        VICAR (``.IMG``/``.VIC``, attached VICAR label), PDS3 label (``.LBL``, or an
        ``.IMG`` with an attached PDS3 label), PDS4 label (``.xml``), FITS, PNG, TIFF,
        JPEG, JPEG 2000.
    min_size
        Smallest accepted side (px).

    Raises
    ------
    ImageReadError
        Missing, empty or unreadable file, corrupt label, no image in the product.
    ImageContentError
        Wrong shape, too small, no measured pixel.
    """
    p = Path(path)
    if not p.is_file():
        raise ImageReadError(f"image file {str(p)!r} does not exist or is not a file")
    if p.stat().st_size == 0:
        raise ImageReadError(f"image file {str(p)!r} is empty (0 bytes)")
    head = _head(p)
    if head.startswith(_VICAR_MAGIC):
        raw, label = _read_vicar(p)
        return _frame_from_array(p, raw, label, "vicar", min_size)
    if head.lstrip().startswith(_PDS3_MAGIC) or p.suffix.lower() == ".xml":
        raw, label = _read_pds(p)
        return _frame_from_array(p, raw, label, "pds4" if p.suffix.lower() == ".xml" else "pds3", min_size)
    return _frame_from_file(p, min_size)


__all__ = ["MIN_FILL_RUN", "Frame", "FrameMeta", "meta_from_label", "read_frame", "validity_mask"]
