"""One validation layer for every value that enters jaxlimb from outside.

Numbers, vectors, input and output paths and memory budgets are checked here, by the
library's constructors (:class:`~jaxlimb.geometry.camera.Camera`,
:class:`~jaxlimb.imaging.Hints`, the ``*Options`` dataclasses) and by every CLI
sub-command's argument parser, so that a class of bad input is refused in one place:

* a number is a real number -- never a ``bool`` (``True`` is not 1 mm), never a string
  that happens to parse (``"3.08"``), never NaN or infinite -- inside a stated
  :class:`Range`; the message names the argument, the allowed range and the value;
* an input file exists, is a regular file (a directory is not "missing", it is a
  directory) and is readable;
* an output file's directory exists and accepts a file (probed by creating one), the path
  is not a directory, and its extension is one the writer knows -- all before any
  computation, so a result is never computed and then lost;
* a computation whose memory estimate exceeds what the machine (or the cgroup / rlimit)
  has available is refused before it allocates.

Every failure is a :class:`~jaxlimb.errors.LimbInputError` subclass (CLI exit 2); CLI
flags use :func:`arg_number`, whose :class:`argparse.ArgumentTypeError` the parser turns
into ``jaxlimb <cmd>: error: argument --tol: must be ...`` (exit 2).
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import math
import numbers
import os
import resource
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import CenterTooUncertainError, ConfigError, LimbInputError


# ----------------------------------------------------------------------------- numbers
@dataclass(frozen=True)
class Range:
    """An interval of allowed values; ``None`` = unbounded on that side."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def __contains__(self, x: float) -> bool:
        if self.lo is not None and (x < self.lo or (self.lo_open and x == self.lo)):
            return False
        return not (self.hi is not None and (x > self.hi or (self.hi_open and x == self.hi)))

    def __str__(self) -> str:
        if self.lo is None and self.hi is None:
            return ""
        if self.hi is None:
            return f"{'>' if self.lo_open else '>='} {_fmt(self.lo)}"
        if self.lo is None:
            return f"{'<' if self.hi_open else '<='} {_fmt(self.hi)}"
        return f"in {'(' if self.lo_open else '['}{_fmt(self.lo)}, {_fmt(self.hi)}{')' if self.hi_open else ']'}"


def _fmt(x: float) -> str:
    """``4294967295`` rather than ``4.29497e+09``; ``0.5``, ``1e-09`` as ``%g``."""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e16 else f"{x:g}"


#: Extensions a figure may be saved with (matplotlib back ends available offline).
FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff")

ANY = Range()
POSITIVE = Range(0.0, lo_open=True)
NON_NEGATIVE = Range(0.0)


def is_real(value: Any) -> bool:
    """True for a real number (Python or NumPy scalar) that is not a boolean."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def number(value: Any, name: str, rng: Range = ANY, *, integer: bool = False,
           error: type[LimbInputError] = ConfigError) -> Any:
    """``value`` as a finite ``float`` (or ``int`` when ``integer``) inside ``rng``.

    Raises ``error`` naming ``name``, the allowed range and the value for a bool, a string
    (even ``"3.08"``), any non-number, a non-integer where an integer is needed, NaN, an
    infinity or a value outside ``rng``.
    """
    if not is_real(value) or (integer and not isinstance(value, numbers.Integral)):
        got = f"{type(value).__name__} {value!r}" if isinstance(value, (bool, np.bool_, str)) else repr(value)
        raise error(f"{name} must be {_kind(rng, integer)}, got {got}")
    x = int(value) if integer else float(value)
    if not math.isfinite(x) or x not in rng:
        raise error(f"{name} must be {_kind(rng, integer)}, got {value!r}")
    return x


def _kind(rng: Range, integer: bool) -> str:
    """``"a finite number in [0, 1]"``, ``"an integer >= 2"``, ..."""
    return ("an integer" if integer else "a finite number") + (f" {rng}" if str(rng) else "")


def vector(value: Any, name: str, n: int, rng: Range = ANY, *,
           error: type[LimbInputError] = ConfigError) -> tuple[float, ...]:
    """A sequence of exactly ``n`` finite real numbers (no bools, no strings) inside ``rng``."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, Sequence) or isinstance(value, (str, bytes)) or len(value) != n:
        raise error(f"{name} must be a list of {n} numbers, got {value!r}")
    return tuple(number(v, f"{name}[{i}]", rng, error=error) for i, v in enumerate(value))


def matrix(value: Any, name: str, shape: tuple[int, int], *,
           error: type[LimbInputError] = ConfigError) -> tuple[tuple[float, ...], ...]:
    """A ``shape[0]`` x ``shape[1]`` nested list of finite real numbers."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, Sequence) or isinstance(value, (str, bytes)) or len(value) != shape[0]:
        raise error(f"{name} must be a {shape[0]}x{shape[1]} matrix (list of rows), got {value!r}")
    return tuple(vector(row, f"{name}[{i}]", shape[1], error=error) for i, row in enumerate(value))


def real_array(value: Any, name: str, *, error: type[LimbInputError] = ConfigError) -> np.ndarray:
    """A (nested) list of finite real numbers -- no bools, no strings -- as a float array of any shape."""

    def walk(v: Any, where: str) -> Any:
        if isinstance(v, (list, tuple)):
            return [walk(x, f"{where}[{i}]") for i, x in enumerate(v)]
        return number(v, where, error=error)

    out = walk(value.tolist() if isinstance(value, np.ndarray) else value, name)
    try:
        return np.asarray(out, dtype=float)
    except ValueError:  # ragged
        raise error(f"{name} must be a rectangular array of numbers, got {value!r}") from None


def near_key(name: str, known: Sequence[str]) -> str | None:
    """The known key ``name`` most likely misspells (a known key it begins, with at least 4 characters and 40 % of
    that key, or a close match), else ``None``."""
    name = str(name)
    starts = [k for k in known if k.startswith(name) and len(name) >= max(4, 0.4 * len(k))]
    close = difflib.get_close_matches(name, list(known), 1, 0.7)
    return starts[0] if starts else (close[0] if close else None)


def arg_number(rng: Range = ANY, *, integer: bool = False) -> Callable[[str], Any]:
    """An argparse ``type=`` for a CLI flag: a finite number (or integer) inside ``rng``.

    ``argparse`` reports the failure as ``argument --flag: must be ... got '...'`` (exit 2).
    """

    def parse(text: str) -> Any:
        try:  # plain ASCII decimal only: not "1_000", not Unicode digits, not surrounding blanks
            if not text.isascii() or "_" in text or text != text.strip():
                raise ValueError(text)
            x = int(text) if integer else float(text)
        except ValueError:
            x = math.nan
        if not math.isfinite(x) or x not in rng:
            raise argparse.ArgumentTypeError(f"must be {_kind(rng, integer)}, got {text!r}")
        return x

    parse.__name__ = "integer" if integer else "number"
    return parse


# ----------------------------------------------------------------------------- paths
def input_file(path: str | os.PathLike[str], name: str, *,
               error: type[LimbInputError] = LimbInputError) -> Path:
    """An existing, readable regular file (a directory is refused as a directory)."""
    p = Path(path)
    if not str(path).strip():
        raise error(f"{name} is an empty path")
    if p.is_dir():
        raise error(f"{name} {str(p)!r} is a directory, not a file")
    if not p.exists():
        raise error(f"{name} {str(p)!r} does not exist")
    if not p.is_file():
        raise error(f"{name} {str(p)!r} is not a regular file")
    if not os.access(p, os.R_OK):
        raise error(f"{name} {str(p)!r} is not readable")
    return p


def _probe_writable_dir(d: Path) -> str | None:
    """None when a file can be created in directory ``d``, else the reason."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".jaxlimb-probe.", dir=d)
    except OSError as e:
        return e.strerror or str(e)
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(tmp)
    return None


def output_file(path: str | os.PathLike[str], name: str, *, suffixes: Sequence[str] | None = None,
                error: type[LimbInputError] = LimbInputError) -> Path:
    """Check that ``path`` can be written, before any work is done.

    The path must not be a directory nor anything else that is not a regular file (a FIFO, a
    device), its extension must be one of ``suffixes`` (when given, lower-case with the dot),
    and its directory must exist and accept a new file.
    """
    p = Path(path)
    if not str(path).strip():
        raise error(f"{name} is an empty path")
    if p.is_dir():
        raise error(f"{name} {str(p)!r} is a directory; give a file name")
    if p.exists() and not p.is_file():  # a FIFO would block the writer for ever, a device swallow the result
        raise error(f"{name} {str(p)!r} is not a regular file (a FIFO, socket or device); give a file name")
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise error(f"{name} {str(p)!r} has extension {p.suffix or '(none)'!r}; use one of {', '.join(suffixes)}")
    parent = p.parent
    if not parent.exists():
        raise error(f"{name} {str(p)!r}: directory {str(parent)!r} does not exist")
    if not parent.is_dir():
        raise error(f"{name} {str(p)!r}: {str(parent)!r} is not a directory")
    reason = _probe_writable_dir(parent)
    if reason is not None:
        raise error(f"{name} {str(p)!r}: cannot write in {str(parent)!r} ({reason})")
    if p.exists() and not os.access(p, os.W_OK):
        raise error(f"{name} {str(p)!r} exists and is not writable")
    return p


def output_dir(path: str | os.PathLike[str], name: str, *,
               error: type[LimbInputError] = LimbInputError) -> Path:
    """An output directory (made later if missing): not a file, its nearest existing
    ancestor a directory that accepts a new entry.  Relative paths are relative to the
    current directory; the absolute path is returned."""
    if not str(path).strip():
        raise error(f"{name} is an empty path")
    p = Path(path).expanduser().absolute()
    if p.exists() and not p.is_dir():
        raise error(f"{name} {str(path)!r} exists and is not a directory")
    anc = p
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise error(f"{name} {str(path)!r}: {str(anc)!r} is not a directory")
    reason = _probe_writable_dir(anc)
    if reason is not None:
        raise error(f"{name} {str(path)!r}: cannot write in {str(anc)!r} ({reason})")
    return p


# ----------------------------------------------------------------------------- memory
def _meminfo_available() -> float:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return math.inf


def _cgroup_available() -> float:
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = float(Path("/sys/fs/cgroup/memory.current").read_text().strip())
    except (OSError, ValueError):
        return math.inf
    return math.inf if limit == "max" else float(limit) - used


def _rlimit_available() -> float:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return math.inf
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return float(soft) - float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return float(soft)


def available_memory() -> float:
    """Bytes this process can still allocate: the least of MemAvailable, the cgroup's
    remaining ``memory.max`` and the address-space rlimit's remainder (``inf`` if unknown)."""
    return max(0.0, min(_meminfo_available(), _cgroup_available(), _rlimit_available()))


def _gib(n: float) -> str:
    return f"{n / 2**30:.2f} GiB" if n >= 2**27 else f"{n / 2**20:.0f} MiB"


def check_memory(nbytes: float, what: str, *, fraction: float = 0.5,
                 error: type[LimbInputError] = LimbInputError) -> None:
    """Refuse (``error``) when ``what`` would need more than ``fraction`` of the available memory."""
    avail = available_memory()
    if nbytes > fraction * avail:
        raise error(f"{what} needs about {_gib(nbytes)} of memory; only {_gib(fraction * avail)} "
                    f"({fraction:.0%} of the {_gib(avail)} available) may be used")


def check_center_sigma(cov_rc: np.ndarray, tol_px: float | None) -> float:
    """The centre's 1-sigma (px, the larger axis of its 2x2 covariance) must be finite and <= ``tol_px``."""
    c = np.asarray(cov_rc, float)
    s = float(math.sqrt(max(float(np.max(np.linalg.eigvalsh(0.5 * (c + c.T)))), 0.0))) if np.all(np.isfinite(c)) \
        else math.inf
    if not math.isfinite(s) or (tol_px is not None and s > tol_px):
        raise CenterTooUncertainError(
            f"the centre's 1-sigma is {s:.4g} px, above max_center_sigma_px = {tol_px} px: the frame does not measure "
            "the centre to the stated tolerance (raise it, --max-center-sigma-px PX|none on the command line, to accept "
            "the centre with its covariance)")
    return s


__all__ = [
    "near_key",
    "ANY",
    "FIGURE_SUFFIXES",
    "NON_NEGATIVE",
    "POSITIVE",
    "Range",
    "arg_number",
    "available_memory",
    "check_center_sigma",
    "check_memory",
    "input_file",
    "is_real",
    "matrix",
    "number",
    "output_dir",
    "output_file",
    "real_array",
    "vector",
]
