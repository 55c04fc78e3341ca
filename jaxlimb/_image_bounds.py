"""Image sizes read from file headers and checked before any pixel is decoded.

A decoder allocates what the header declares: a 467-byte PNG can declare 100 000 x 100 000 px and a
valid 880 kB PNG inflates to 30 000 x 30 000 px (6.7 GiB once converted to float64).  Every reader of
jaxlimb first reads the declared size from the header -- PNG ``IHDR``, JPEG ``SOFn``, TIFF/BigTIFF
first IFD, JPEG 2000 ``ihdr`` box or ``SIZ`` marker, BMP, PNM, FITS ``NAXISn``/``BITPIX`` (the
decompressed size of a tile-compressed HDU), VICAR ``NL``/``NS``/``NB``/``FORMAT``, PDS3 ``LINES``/
``LINE_SAMPLES``/``SAMPLE_BITS`` -- and refuses, with :class:`~jaxlimb.errors.ImageReadError` (CLI
exit 2) and nothing allocated, an image

* of more than :data:`MAX_IMAGE_PIXELS` pixels (16384 x 16384), or
* whose decoding and float64 working copies (:meth:`HeaderSize.working_bytes`) would need more than
  half of the memory this process may still allocate (:func:`jaxlimb._validate.check_memory`).

Formats whose header is not read here (anything else OpenCV decodes) are bounded by OpenCV's own
``OPENCV_IO_MAX_IMAGE_PIXELS``, set to :data:`MAX_IMAGE_PIXELS` before OpenCV is imported by the
command line.
"""

from __future__ import annotations

import math
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path

from .errors import ImageReadError, LabelError

#: Most pixels of an image jaxlimb decodes (16384 x 16384; the largest mission frames are ~2.6e8).
MAX_IMAGE_PIXELS = 1 << 28
#: float64 copies of the frame a measurement holds at once (grey conversion, validation, masks, gradients).
FLOAT64_COPIES = 4


@dataclass(frozen=True)
class HeaderSize:
    """The size an image file declares: ``rows`` x ``cols`` pixels of ``channels`` samples of ``sample_bytes``."""

    rows: int
    cols: int
    channels: int = 1
    sample_bytes: int = 1
    format: str = ""

    @property
    def pixels(self) -> int:
        return self.rows * self.cols

    @property
    def decoded_bytes(self) -> int:
        return self.pixels * self.channels * self.sample_bytes

    @property
    def working_bytes(self) -> int:
        """Bytes of the decoded samples plus the float64 working copies (:data:`FLOAT64_COPIES`)."""
        return self.decoded_bytes + self.pixels * 8 * FLOAT64_COPIES


def check_size(size: HeaderSize | None, path: str | os.PathLike[str]) -> None:
    """Refuse (:class:`~jaxlimb.errors.ImageReadError`) an image too large to decode (module docstring)."""
    from ._validate import check_memory

    if size is None:
        return
    what = f"image {str(path)!r} ({size.format} header: {size.rows} x {size.cols} px x {size.channels} channel(s))"
    if size.rows <= 0 or size.cols <= 0:
        raise ImageReadError(f"{what} declares an empty image")
    if size.pixels > MAX_IMAGE_PIXELS:
        raise ImageReadError(f"{what} has {size.pixels:.3g} pixels, more than the {MAX_IMAGE_PIXELS:.3g} "
                             "(16384 x 16384) jaxlimb decodes: refused before decoding")
    check_memory(size.working_bytes, f"decoding {what}", error=ImageReadError)


def header_size(path: str | os.PathLike[str]) -> HeaderSize | None:
    """The size declared by the header of a PNG, JPEG, TIFF, JPEG 2000, BMP or PNM file (by its magic bytes),
    ``None`` for any other file; a header too short or inconsistent to read is an
    :class:`~jaxlimb.errors.ImageReadError`."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(64)
            for magic, reader in _READERS:
                if head.startswith(magic):
                    return reader(fh, head)
    except (struct.error, ValueError, IndexError, OSError) as e:
        raise ImageReadError(f"image file {str(p)!r} has a corrupt header ({type(e).__name__}: {e})") from None
    return None


def check_file(path: str | os.PathLike[str]) -> None:
    """:func:`check_size` of whatever size the file's header declares (PNG, JPEG, TIFF, JPEG 2000, BMP, PNM,
    VICAR; FITS by :func:`fits_size` of each HDU); cheap (a few header bytes), without JAX, NumPy
    decoding or OpenCV, so a command can refuse a bomb before it starts anything else."""
    p = Path(path)
    if not p.is_file():
        return  # the reader says what is wrong with it
    with open(p, "rb") as fh:
        head = fh.read(16)
    if head.startswith(b"LBLSIZE="):
        check_size(vicar_size(p), p)
    elif head.startswith(b"SIMPLE  ="):
        for size in fits_file_sizes(p):
            check_size(size, p)
    else:
        check_size(header_size(p), p)


# ----------------------------------------------------------------------------- per format
def _png(fh, head: bytes) -> HeaderSize:  # noqa: ANN001
    if head[12:16] != b"IHDR":
        raise ValueError("no IHDR chunk first")
    cols, rows, depth, colour = struct.unpack(">IIBB", head[16:26])
    channels = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}.get(colour)  # a palette is decoded to 3 channels
    if channels is None:
        raise ValueError(f"colour type {colour}")
    return HeaderSize(rows, cols, channels, 2 if depth == 16 else 1, "PNG")


_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _jpeg(fh, head: bytes) -> HeaderSize:  # noqa: ANN001
    fh.seek(2)
    for _ in range(4096):  # segments before the frame header (APPn, tables...)
        marker = fh.read(2)
        while marker[:1] == b"\xff" and marker[1:2] == b"\xff":  # fill bytes
            marker = marker[1:] + fh.read(1)
        if len(marker) < 2 or marker[0] != 0xFF:
            raise ValueError("no frame header (SOFn)")
        if 0xD0 <= marker[1] <= 0xD9 or marker[1] == 0x01:  # markers without a length
            continue
        (length,) = struct.unpack(">H", fh.read(2))
        if marker[1] in _SOF:
            bits, rows, cols, comps = struct.unpack(">BHHB", fh.read(6))
            return HeaderSize(rows, cols, comps, 2 if bits > 8 else 1, "JPEG")
        fh.seek(length - 2, os.SEEK_CUR)
    raise ValueError("no frame header (SOFn) in the first 4096 segments")


def _tiff(fh, head: bytes) -> HeaderSize:  # noqa: ANN001
    e = "<" if head[:2] == b"II" else ">"
    (version,) = struct.unpack(e + "H", head[2:4])
    if version == 43:  # BigTIFF: 8-byte entry counts, value counts and offsets
        (offset,) = struct.unpack(e + "Q", head[8:16])
        n_fmt, cnt_bytes, field_fmt = "Q", 8, "Q"
    else:
        (offset,) = struct.unpack(e + "I", head[4:8])
        n_fmt, cnt_bytes, field_fmt = "H", 4, "I"
    fh.seek(offset)
    (n,) = struct.unpack(e + n_fmt, fh.read(struct.calcsize(n_fmt)))
    if n > 4096:
        raise ValueError(f"{n} tags in the first IFD")
    tags: dict[int, int] = {}
    for _ in range(n):
        entry = fh.read(4 + cnt_bytes + struct.calcsize(field_fmt))
        tag, typ = struct.unpack(e + "HH", entry[:4])
        raw = entry[4 + cnt_bytes :]
        fmt = {3: "H", 4: "I", 16: "Q"}.get(typ, field_fmt)  # values are left-justified in the value field
        tags[tag] = struct.unpack(e + fmt, raw[: struct.calcsize(fmt)])[0]
    if 256 not in tags or 257 not in tags:
        raise ValueError("no ImageWidth/ImageLength tag")
    bits = tags.get(258, 1) if tags.get(277, 1) == 1 else 16  # several samples: BitsPerSample is an offset
    return HeaderSize(tags[257], tags[256], max(1, tags.get(277, 1)), 2 if bits > 8 else 1, "TIFF")


def _jp2(fh, head: bytes) -> HeaderSize:  # noqa: ANN001
    if head.startswith(b"\xff\x4f\xff\x51"):  # a raw codestream: the SIZ marker segment
        xsiz, ysiz, xo, yo = struct.unpack(">IIII", head[8:24])
        (comps,) = struct.unpack(">H", head[40:42])
        return HeaderSize(ysiz - yo, xsiz - xo, comps, 2, "JPEG 2000")
    fh.seek(0)
    data = fh.read(1 << 16)
    i = data.find(b"ihdr")
    if i < 4:
        raise ValueError("no ihdr box in the first 64 KiB")
    rows, cols, comps, bpc = struct.unpack(">IIHB", data[i + 4 : i + 15])
    return HeaderSize(rows, cols, comps, 2 if (bpc & 0x7F) >= 8 else 1, "JPEG 2000")


def _bmp(fh, head: bytes) -> HeaderSize:  # noqa: ANN001
    cols, rows, _, bpp = struct.unpack("<iiHH", head[18:30])
    return HeaderSize(abs(rows), abs(cols), 4 if bpp == 32 else 3 if bpp > 8 else 1, 1, "BMP")


_PNM_TOKENS = re.compile(rb"(?:\s|#[^\n]*\n)*(\d+)")


def _pnm(fh, head: bytes) -> HeaderSize:  # noqa: ANN001
    fh.seek(2)
    text = fh.read(1024)
    nums = [int(m) for m in _PNM_TOKENS.findall(text)[:3]]
    if len(nums) < 2:
        raise ValueError("no width/height")
    maxval = nums[2] if len(nums) > 2 else 1
    return HeaderSize(nums[1], nums[0], 3 if head[1:2] in (b"3", b"6") else 1, 2 if maxval > 255 else 1, "PNM")


_READERS = (
    (b"\x89PNG\r\n\x1a\n", _png),
    (b"\xff\xd8", _jpeg),
    (b"II*\x00", _tiff), (b"MM\x00*", _tiff), (b"II+\x00", _tiff), (b"MM\x00+", _tiff),
    (b"\x00\x00\x00\x0cjP  ", _jp2), (b"\xff\x4f\xff\x51", _jp2),
    (b"BM", _bmp),
    (b"P2", _pnm), (b"P3", _pnm), (b"P5", _pnm), (b"P6", _pnm),
)


# ----------------------------------------------------------------------------- labelled formats
_FITS_BYTES = {8: 1, 16: 2, 32: 4, 64: 8, -32: 4, -64: 8}


def fits_size(header, path: str | os.PathLike[str]) -> HeaderSize | None:  # noqa: ANN001
    """The size of a FITS HDU's image from its header (``NAXISn``, ``BITPIX``; astropy gives a
    tile-compressed HDU's image header), ``None`` for an HDU without an image of 2+ axes."""
    try:
        naxis = int(header.get("NAXIS", 0))
        dims = [int(header.get(f"NAXIS{i}", 0)) for i in range(1, naxis + 1)]
        sample = _FITS_BYTES.get(int(header.get("BITPIX", 8)), 8)
    except (TypeError, ValueError):
        raise ImageReadError(f"FITS file {str(path)!r} has a corrupt NAXIS/BITPIX header") from None
    if naxis < 2:
        return None
    extra = 1
    for d in dims[2:]:
        extra *= max(d, 1)
    return HeaderSize(dims[1], dims[0], extra, sample, "FITS")


_CARD = re.compile(rb"^([A-Z0-9_-]{1,8})\s*=\s*'?\s*([^'/]*?)\s*'?\s*(?:/.*)?$")


def fits_file_sizes(path: str | os.PathLike[str], max_hdus: int = 1000) -> list[HeaderSize]:
    """The image sizes the headers of an uncompressed FITS file declare, HDU after HDU (a tile-compressed
    image by its ``ZNAXISn``/``ZBITPIX``), read card by card without astropy and without the data; a
    header cut short ends the walk (the reader reports the file)."""
    out: list[HeaderSize] = []
    p = Path(path)
    with open(p, "rb") as fh:
        for _ in range(max_hdus):
            cards: dict[bytes, bytes] = {}
            while True:
                block = fh.read(2880)
                if len(block) < 2880:
                    return out
                for i in range(0, 2880, 80):
                    m = _CARD.match(block[i : i + 80].rstrip())
                    if m:
                        cards.setdefault(m.group(1), m.group(2))
                if any(block[i : i + 80].rstrip() == b"END" for i in range(0, 2880, 80)):
                    break
            try:
                z = b"Z" if cards.get(b"ZIMAGE", b"") == b"T" else b""
                hdr = {"NAXIS": int(cards.get(z + b"NAXIS", b"0")), "BITPIX": int(cards.get(z + b"BITPIX", b"8"))}
                hdr.update({f"NAXIS{i}": int(cards.get(z + b"NAXIS%d" % i, b"0")) for i in range(1, hdr["NAXIS"] + 1)})
                if z:  # the table that holds the tiles
                    hdu_naxis = [int(cards.get(b"NAXIS%d" % i, b"0")) for i in (1, 2)]
                    data = hdu_naxis[0] * hdu_naxis[1] + int(cards.get(b"PCOUNT", b"0"))
                else:
                    data = abs(hdr["BITPIX"]) // 8 * math.prod(hdr[f"NAXIS{i}"] for i in range(1, hdr["NAXIS"] + 1)) \
                        if hdr["NAXIS"] else 0
            except ValueError:
                raise ImageReadError(f"FITS file {str(p)!r} has a corrupt NAXIS/BITPIX header card") from None
            size = fits_size(hdr, p)
            if size is not None:
                out.append(size)
            fh.seek(-(-data // 2880) * 2880, os.SEEK_CUR)
    return out


_VICAR_KEYS = re.compile(rb"\b(LBLSIZE|NL|NS|NB|NBB|NLB|RECSIZE|FORMAT)\s*=\s*'?([A-Z0-9]+)'?")
_VICAR_BYTES = {b"BYTE": 1, b"HALF": 2, b"WORD": 2, b"FULL": 4, b"LONG": 4, b"REAL": 4, b"DOUB": 8, b"COMP": 8}


def vicar_size(path: str | os.PathLike[str]) -> HeaderSize:
    """The size a VICAR label declares (``NL`` x ``NS`` x ``NB`` of ``FORMAT``), checked against the file:
    a label that declares more data than the file holds, or garbles its sizes, is a
    :class:`~jaxlimb.errors.LabelError`."""
    p = Path(path)
    with open(p, "rb") as fh:
        head = fh.read(1 << 16)
    keys: dict[bytes, bytes] = {}
    for k, v in _VICAR_KEYS.findall(head[: head.find(b"\0") if b"\0" in head else len(head)]):
        keys.setdefault(k, v)
    try:
        lbl, nl, ns = (int(keys[k]) for k in (b"LBLSIZE", b"NL", b"NS"))
        nb, nbb, nlb = (int(keys.get(k, d)) for k, d in ((b"NB", b"1"), (b"NBB", b"0"), (b"NLB", b"0")))
        sample = _VICAR_BYTES[keys.get(b"FORMAT", b"BYTE")]
    except (KeyError, ValueError):
        raise LabelError(f"VICAR file {str(p)!r}: the label lacks or garbles LBLSIZE/NL/NS/NB/FORMAT") from None
    recsize = int(keys.get(b"RECSIZE", str(nbb + ns * sample).encode()))
    need = lbl + (nlb + nl * nb) * recsize
    have = p.stat().st_size
    if min(nl, ns, nb) <= 0 or need > have:
        raise LabelError(f"VICAR file {str(p)!r} declares {nl} x {ns} x {nb} samples ({need} bytes with its "
                             f"label), the file holds {have}: truncated or a corrupt label")
    return HeaderSize(nl, ns, nb, sample, "VICAR")


__all__ = ["FLOAT64_COPIES", "MAX_IMAGE_PIXELS", "HeaderSize", "check_file", "check_size", "fits_file_sizes", "fits_size",
           "header_size", "vicar_size"]
