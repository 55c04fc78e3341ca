"""Hostile inputs made by the fault tests (and ``benchmarks/faults.py``): decompression bombs -- small files
whose headers declare huge images -- and a program that fills the compilation and export caches."""

from __future__ import annotations

import contextlib
import os
import signal
import struct
import subprocess
import sys
import zlib
from collections.abc import Iterator
from pathlib import Path

HUGE = 100_000  # px per side: 10^10 pixels


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def png(rows: int, cols: int, idat: bytes) -> bytes:
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", cols, rows, 8, 0, 0, 0, 0))
            + _chunk(b"IDAT", idat) + _chunk(b"IEND", b""))


def inflating_png(rows: int, cols: int, k: int = 64) -> bytes:
    """A *valid* PNG of ``rows`` x ``cols`` black pixels, a few hundred kB: one fully flushed raw-deflate block
    of ``k`` zero rows repeated (the Adler-32 of N zero bytes is ``(N mod 65521) << 16 | 1``)."""
    zero_rows = b"\0" * ((cols + 1) * k)
    co = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = co.compress(zero_rows) + co.flush(zlib.Z_FULL_FLUSH)
    n, rest = divmod(rows, k)
    tail = co.compress(b"\0" * ((cols + 1) * rest)) + co.flush()
    adler = (((cols + 1) * rows) % 65521) << 16 | 1
    return png(rows, cols, b"\x78\xda" + block * n + tail + struct.pack(">I", adler))


def tiff(rows: int, cols: int, big: bool = False) -> bytes:
    tags = [(256, 4, cols), (257, 4, rows), (258, 3, 8), (259, 3, 1), (262, 3, 1), (277, 3, 1), (273, 4, 0)]
    if not big:
        ifd = struct.pack("<H", len(tags)) + b"".join(struct.pack("<HHII", t, typ, 1, v if typ == 4 else v) if typ == 4
                                                      else struct.pack("<HHIHH", t, typ, 1, v, 0) for t, typ, v in tags)
        return b"II*\x00" + struct.pack("<I", 8) + ifd + b"\0" * 8
    ifd = struct.pack("<Q", len(tags)) + b"".join(struct.pack("<HHQQ", t, typ, 1, v) for t, typ, v in tags)
    return b"II+\x00" + struct.pack("<HHQ", 8, 0, 16) + ifd + b"\0" * 8


def jpeg(rows: int, cols: int) -> bytes:
    sof = struct.pack(">BHHB", 8, rows, cols, 1) + bytes([1, 0x11, 0])
    return b"\xff\xd8" + b"\xff\xe0" + struct.pack(">H", 16) + b"JFIF\0" + b"\0" * 9 + \
        b"\xff\xc0" + struct.pack(">H", 2 + len(sof)) + sof + b"\xff\xd9"


def jp2(rows: int, cols: int) -> bytes:
    ihdr = struct.pack(">IIHBBBB", rows, cols, 1, 7, 7, 0, 0)
    jp2h = struct.pack(">I", 8 + 8 + len(ihdr)) + b"jp2h" + struct.pack(">I", 8 + len(ihdr)) + b"ihdr" + ihdr
    return b"\x00\x00\x00\x0cjP  \r\n\x87\n" + struct.pack(">I", 20) + b"ftypjp2 \0\0\0\0jp2 " + jp2h


def bmp(rows: int, cols: int) -> bytes:
    return b"BM" + struct.pack("<IHHI", 54, 0, 0, 54) + struct.pack("<IiiHHIIiiII", 40, cols, rows, 1, 8, 0, 0, 0, 0, 0, 0)


def pgm(rows: int, cols: int) -> bytes:
    return f"P5\n# a comment\n{cols} {rows}\n255\n".encode() + b"\0" * 16


def fits(rows: int, cols: int) -> bytes:
    cards = ["SIMPLE  =                    T", "BITPIX  =                   16", "NAXIS   =                    2",
             f"NAXIS1  = {cols:20d}", f"NAXIS2  = {rows:20d}", "END"]
    return "".join(c.ljust(80) for c in cards).ljust(2880).encode()


def vicar(rows: int, cols: int) -> bytes:
    label = f"LBLSIZE=200  FORMAT='BYTE'  TYPE='IMAGE'  NL={rows}  NS={cols}  NB=1  NBB=0  NLB=0  RECSIZE={cols}"
    return label.ljust(200).encode() + b"\0" * 64


MAKERS = {"png": (".png", png), "tiff": (".tif", tiff), "bigtiff": (".tif", lambda r, c: tiff(r, c, big=True)),
          "jpeg": (".jpg", jpeg), "jp2": (".jp2", jp2), "bmp": (".bmp", bmp), "pgm": (".pgm", pgm),
          "fits": (".fits", fits), "vicar": (".img", vicar)}


def write_bomb(folder: Path, kind: str, rows: int = HUGE, cols: int = HUGE) -> Path:
    """``folder/bomb_KIND.EXT`` declaring ``rows`` x ``cols`` (a JPEG at most 65535 per side)."""
    suffix, make = MAKERS[kind]
    if kind == "jpeg":
        rows, cols = min(rows, 65535), min(cols, 65535)
    p = folder / f"bomb_{kind}{suffix}"
    data = make(rows, cols) if kind != "png" else png(rows, cols, zlib.compress(b"\0" * 100))
    p.write_bytes(data)
    return p


#: A script that compiles a program and exports a core through the caches of ``JAXLIMB_CACHE_DIR`` and prints
#: the answers (hex floats), its seconds and the cache warnings it saw, as JSON.
CACHED_PROGRAM = """
import json, sys, time, warnings
t0 = time.perf_counter()
with warnings.catch_warnings(record=True) as seen:
    warnings.simplefilter("always")
    from jaxlimb._jaxcache import start_jax
    start_jax()
    import jax, jax.numpy as jnp, numpy as np
    from jaxlimb.fitting._aot import ExportedCore
    def core(x):
        return {"y": jnp.cos(x) * 0.5 + jnp.sum(x * x), "n": jnp.linalg.norm(x)}
    x = jnp.linspace(0.0, 2.0, 9)
    out = ExportedCore(core, "faults-test-core", lambda x: {"y": x, "n": x})(x)
    z = jax.jit(lambda v: jnp.exp(v) / (1.0 + v * v))(x)
print(json.dumps({"y": [float(v).hex() for v in np.asarray(out["y"])], "n": float(out["n"]).hex(),
                  "z": [float(v).hex() for v in np.asarray(z)], "s": time.perf_counter() - t0,
                  "warnings": [f"{w.category.__name__}: {w.message}" for w in seen
                               if w.category.__name__ == "CacheRepairWarning"]}))
"""


def damage_cache(cache: Path) -> list[Path]:
    """One flipped bit in every entry of a compilation cache (``*-cache``, ``exported/*.bin``; from the header
    to the last byte), a junk entry, and JAX's ``-atime`` files deleted; returns the damaged entries."""
    entries = sorted(cache.glob("*-cache")) + sorted(cache.glob("exported/*.bin"))
    for i, p in enumerate(entries):
        data = bytearray(p.read_bytes())
        data[(i * 7919) % len(data)] ^= 1 << (i % 8)
        p.write_bytes(bytes(data))
    (cache / "junk-cache").write_bytes(os.urandom(4096))
    for p in cache.glob("*-atime"):
        p.unlink()
    return entries


@contextlib.contextmanager
def stopped_lock_holder(lock: Path) -> Iterator[int]:
    """A process that holds ``flock`` on ``lock`` and is stopped (SIGSTOP) for the block; its pid."""
    code = ("import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
            "fcntl.flock(fd, fcntl.LOCK_EX); print(1, flush=True); time.sleep(3600)")
    with subprocess.Popen([sys.executable, "-c", code, str(lock)], stdout=subprocess.PIPE) as holder:
        try:
            holder.stdout.readline()
            os.kill(holder.pid, signal.SIGSTOP)
            yield holder.pid
        finally:
            holder.kill()
            holder.wait()
