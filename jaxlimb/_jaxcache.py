r"""Compile once: JAX's persistent compilation cache, and compile time measured apart.

Every ``jaxlimb`` command (and any script that calls :func:`enable_compile_cache`) stores the
XLA programs it compiles in a per-user directory, so the second and later processes on the
same camera load them instead of compiling again:

* ``$JAXLIMB_CACHE_DIR`` if set (``off``, ``none``, ``0`` or the empty string disable the
  cache);
* else ``$JAXLIMB_CACHE/jax`` (``JAXLIMB_CACHE``: the root of all of jaxlimb's caches, the
  template databases of :mod:`jaxlimb.irregular.database` included);
* else ``$XDG_CACHE_HOME/jaxlimb/jax``;
* else ``~/.cache/jaxlimb/jax``.

A ``JAX_COMPILATION_CACHE_DIR`` set by the user (JAX's own variable) is left alone.  Every
program is cached however small or quick to compile
(``jax_persistent_cache_min_compile_time_secs = 0``, no minimum entry size): the pipeline is
made of many small programs whose compilation adds up.

Checked entries, no lock.  The compiled programs are stored by :class:`CheckedCache` (installed
in JAX's place, same ``<key>-cache`` file names) and the exported fit cores by
:mod:`jaxlimb.fitting._aot`, both as *sealed* entries (:func:`seal`): a header with the SHA-256 of
the JAX and jaxlib versions and of the entry's bytes.  The seal is checked before anything is
deserialised, so a damaged entry (a flipped bit, a truncated file, junk under an entry's name,
another JAX's entry) never reaches XLA's deserialiser -- which can abort the process -- nor gives a
different answer: it is deleted, the program is compiled again, and one
:class:`~jaxlimb.errors.CacheRepairWarning` says so (once per process).  Entries are written
atomically (a temporary renamed into place), so readers never see half an entry and no lock is
needed: a stale or stopped lock holder cannot hold a run up.  The least recently used entries
(file modification time, touched on every hit) are evicted beyond :data:`MAX_BYTES`; junk files
(evicted like entries) and missing or orphan JAX ``-atime`` files do not stop it storing.  A cache
that cannot be written (a full disk, ``JAXLIMB_CACHE`` naming a file) is bypassed with one
warning; the run goes on without it.

:class:`CompileTimer` measures the wall time spent tracing, lowering and compiling (or loading
from the cache) inside a block, from JAX's monitoring time spans (the union of the spans, so
nested traces are not counted twice): the ``compile_s`` that the commands report apart from
the compute time.
"""

from __future__ import annotations

import contextlib
import os
import threading
from pathlib import Path
from types import TracebackType

ENV_DIR = "JAXLIMB_CACHE_DIR"
"""Environment variable overriding the cache directory (``off`` disables the cache)."""
MAX_BYTES = 2 << 30
"""Size limit of the cache directory (least recently used entries are evicted beyond it)."""
_OFF = frozenset({"", "0", "off", "none", "false", "no"})
_COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity set on Linux, else ``os.cpu_count()``), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def preload_lapack_kernels() -> bool:
    """Load SciPy's ``cython_blas`` / ``cython_lapack`` without the ``scipy.linalg`` package.

    jaxlib finds its CPU LAPACK kernels in these two Cython modules (``GetLapackKernelsFromScipy``)
    the first time a program with a linear-algebra call, or any exported program
    (:mod:`jaxlimb.fitting._aot`), is lowered.  Importing them by name first runs
    ``scipy/linalg/__init__.py``: ~0.1-0.25 s of CPU per process, most of it modules no command
    uses.  Loaded from their own files into ``sys.modules`` under their own names, they are the
    same modules; a later ``import scipy.linalg`` works as usual.  Called by the command line
    before JAX starts; any failure leaves the normal import path (returns False).
    """
    import importlib.util
    import sys

    if "scipy.linalg" in sys.modules:
        return True
    try:
        import scipy

        folder = Path(scipy.__file__).parent / "linalg"
        for name in ("cython_blas", "cython_lapack"):
            full = f"scipy.linalg.{name}"
            if full in sys.modules:
                continue
            path = next(p for p in folder.iterdir() if p.name.startswith(name + ".") and p.suffix in (".so", ".pyd"))
            spec = importlib.util.spec_from_file_location(full, path)
            if spec is None or spec.loader is None:
                return False
            module = importlib.util.module_from_spec(spec)
            sys.modules[full] = module
            try:
                spec.loader.exec_module(module)
            except BaseException:
                del sys.modules[full]
                raise
    except Exception:  # noqa: BLE001 - an optimisation only
        return False
    return True


def cache_dir() -> Path | None:
    """The directory the persistent cache uses, or ``None`` when disabled (module docstring)."""
    env = os.environ.get(ENV_DIR)
    if env is not None:
        return None if env.strip().lower() in _OFF else Path(env).expanduser()
    root = os.environ.get("JAXLIMB_CACHE")
    if root:
        return Path(root).expanduser() / "jax"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "jaxlimb" / "jax"


def enable_compile_cache(path: str | os.PathLike[str] | None = None) -> Path | None:
    """Switch on JAX's persistent compilation cache (before the first compilation).

    Parameters
    ----------
    path : the cache directory (default :func:`cache_dir`).

    Returns
    -------
    The directory in use, or ``None`` (disabled by ``JAXLIMB_CACHE_DIR=off``, or the directory
    cannot be created: the cache is an optimisation, never a reason to fail).
    """
    import jax

    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return Path(os.environ["JAX_COMPILATION_CACHE_DIR"])
    target = Path(path) if path is not None else cache_dir()
    if target is None:
        return None
    try:
        target.mkdir(parents=True, exist_ok=True)
        if not os.access(target, os.W_OK):
            raise PermissionError(13, "not writable")
    except OSError as e:
        warn_once("cache-dir", f"the compilation cache directory {str(target)!r} cannot be used "
                  f"({e.strerror or e}): running without it")
        return None
    jax.config.update("jax_compilation_cache_dir", str(target))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    if not _install_checked_cache(target):  # JAX's own cache then: without a size limit it takes no lock
        jax.config.update("jax_compilation_cache_max_size", -1)
    return target


# ----------------------------------------------------------------------------- sealed entries
_SEAL_MAGIC = b"jaxlimb-sealed-v1\n"
_WARNED: set[str] = set()


def _jax_versions() -> bytes:
    import jax
    import jaxlib

    return f"jax={jax.__version__};jaxlib={jaxlib.__version__}".encode()


def seal(payload: bytes, versions: bytes | None = None) -> bytes:
    """``payload`` with its seal: a magic line and the SHA-256 of ``versions`` (default: JAX's and jaxlib's)
    and of ``payload``; :func:`unseal` gives ``payload`` back only when both match."""
    import hashlib

    v = _jax_versions() if versions is None else versions
    return _SEAL_MAGIC + hashlib.sha256(v + b"\0" + payload).digest() + payload


def unseal(data: bytes, versions: bytes | None = None) -> bytes | None:
    """The payload of a sealed entry, or ``None`` when it is damaged, truncated, not sealed or sealed
    under other versions (:func:`seal`)."""
    import hashlib

    head = len(_SEAL_MAGIC) + 32
    if len(data) < head or not data.startswith(_SEAL_MAGIC):
        return None
    payload = memoryview(data)[head:]
    v = _jax_versions() if versions is None else versions
    if hashlib.sha256(v + b"\0" + payload).digest() != data[len(_SEAL_MAGIC) : head]:
        return None
    return bytes(payload)


def warn_once(kind: str, message: str) -> None:
    """One :class:`~jaxlimb.errors.CacheRepairWarning` per ``kind`` and process (the CLI shows it as one
    ``jaxlimb: warning:`` line)."""
    import warnings

    from .errors import CacheRepairWarning

    if kind not in _WARNED:
        _WARNED.add(kind)
        warnings.warn(message, CacheRepairWarning, stacklevel=3)


def read_sealed(path: Path, what: str, versions: bytes | None = None) -> bytes | None:
    """The checked payload of the sealed entry at ``path``; ``None`` when it is missing.  A damaged or
    foreign entry is deleted (and said once, :func:`warn_once`); so is one that cannot be read."""
    try:
        data = path.read_bytes()
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as e:
        warn_once(what, f"{what} entry {path.name} cannot be read ({e.strerror or e}): compiled again")
        return None
    payload = unseal(data, versions)
    if payload is None:
        with contextlib.suppress(OSError):
            path.unlink()
        warn_once(what, f"{what} entry {path.name} failed its check (damaged, or written by other versions of "
                  "JAX/jaxlib): deleted and compiled again")
    return payload


def write_sealed(path: Path, payload: bytes, what: str, versions: bytes | None = None) -> bool:
    """Write ``payload`` sealed to ``path`` atomically; a failed write (full disk...) is said once and skipped."""
    from ._io import atomic_open

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path, "wb") as fh:
            fh.write(seal(payload, versions))
    except (OSError, ValueError) as e:  # OutputWriteError is a ValueError
        warn_once(what + "-write", f"{what} cannot be written in {str(path.parent)!r} ({e}): running without "
                  "storing its entries")
        return False
    return True


class CheckedCache:
    """JAX's persistent compilation cache with sealed entries, atomic writes and no lock (module docstring).

    The same interface as JAX's own cache (``get``/``put``/``clear`` and ``_path``); installed by
    :func:`enable_compile_cache`.
    """

    what = "compilation cache"

    def __init__(self, path: str | os.PathLike[str], max_bytes: int = MAX_BYTES) -> None:
        self._path = Path(path)
        self.max_bytes = max_bytes
        self._size: int | None = None  # bytes of entries, known after the first put
        self._lock = threading.Lock()

    def _entry(self, key: str) -> Path:
        if not key or "/" in key or key.startswith("."):
            raise ValueError(f"bad cache key {key!r}")
        return self._path / f"{key}-cache"

    def get(self, key: str) -> bytes | None:
        path = self._entry(key)
        value = read_sealed(path, self.what)
        if value is not None:
            with contextlib.suppress(OSError):
                os.utime(path)  # least recently used: the modification time
        return value

    def put(self, key: str, value: bytes) -> None:
        with self._lock:
            if self._size is None:
                self._size = sum(size for _, size, _ in self._entries())
            if self._size + len(value) > self.max_bytes:
                self._evict(self.max_bytes * 9 // 10 - len(value))
            if write_sealed(self._entry(key), value, self.what):
                self._size += len(value)

    def _entries(self) -> list[tuple[int, int, Path]]:
        out = []
        for p in self._path.glob("*-cache"):
            with contextlib.suppress(OSError):
                st = p.stat()
                out.append((st.st_mtime_ns, st.st_size, p))
        return out

    def _evict(self, target: int) -> None:
        entries = sorted(self._entries())
        total = sum(size for _, size, _ in entries)
        for _, size, p in entries:
            if total <= target:
                break
            with contextlib.suppress(OSError):
                p.unlink()
            total -= size
        self._size = total

    def clear(self) -> None:
        for _, _, p in self._entries():
            with contextlib.suppress(OSError):
                p.unlink()
        self._size = 0


def _install_checked_cache(target: Path) -> bool:
    """Put :class:`CheckedCache` in the place JAX's compiler reads and writes its entries (before the first
    compilation); ``False`` (JAX keeps its own cache) when this JAX has no such place or is already using one."""
    try:
        from jax._src import compilation_cache as cc
    except ImportError:  # pragma: no cover - another JAX layout
        return False
    with cc._cache_initialized_mutex:
        if cc._cache_initialized or cc._cache is not None:
            return isinstance(cc._cache, CheckedCache)
        cc._cache = CheckedCache(target)  # type: ignore[assignment]
        cc._cache_initialized = True
    return True


@contextlib.contextmanager
def persistent_cache_bypassed():
    """Compilations in the block neither read nor write JAX's persistent cache.

    ``jax.config``'s ``enable_compilation_cache`` is read once per process, at the first compilation, so setting it
    later does nothing; this block sets the state that reading left (``compilation_cache._cache_used``) and restores
    it.  Needed where an executable is serialised (:func:`jaxlimb._programs.compile_and_store`): one loaded from the
    persistent cache serialises without its functions (``NOT_FOUND: Function ... not found`` when the copy runs).
    Another thread compiling meanwhile compiles without the cache: slower, never wrong.
    """
    try:
        from jax._src import compilation_cache as cc
    except ImportError:  # pragma: no cover - another JAX layout
        yield
        return
    with cc._cache_initialized_mutex:
        saved = (cc._cache_checked, cc._cache_used)
        cc._cache_checked, cc._cache_used = True, False
    try:
        yield
    finally:
        with cc._cache_initialized_mutex:
            cc._cache_checked, cc._cache_used = saved


def start_jax() -> None:
    """JAX as jaxlimb runs it (the command line, Dask workers, pipeline trials): SciPy's LAPACK kernels
    preloaded before JAX is imported (:func:`preload_lapack_kernels`), float64, and the persistent
    compilation cache (:func:`enable_compile_cache`); idempotent."""
    preload_lapack_kernels()
    import jax

    jax.config.update("jax_enable_x64", True)
    enable_compile_cache()


class CompileTimer:
    """Context manager: seconds spent compiling (trace + lower + XLA compile or cache load) in the block.

    Examples
    --------
    >>> with CompileTimer() as ct:  # doctest: +SKIP
    ...     run()
    >>> ct.seconds  # doctest: +SKIP
    """

    def __init__(self) -> None:
        self._spans: list[tuple[float, float]] = []
        self._lock = threading.Lock()

    def _listen(self, event: str, start: float, end: float, **kwargs: object) -> None:
        del kwargs
        if event in _COMPILE_EVENTS:
            with self._lock:
                self._spans.append((start, end))

    def __enter__(self) -> CompileTimer:
        import jax.monitoring

        jax.monitoring.register_event_time_span_listener(self._listen)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        import jax.monitoring

        jax.monitoring.unregister_event_time_span_listener(self._listen)

    @property
    def seconds(self) -> float:
        """Length of the union of the compile spans seen so far."""
        with self._lock:
            spans = sorted(self._spans)
        total, cur_s, cur_e = 0.0, None, None
        for s, e in spans:
            if cur_e is None or s > cur_e:
                if cur_e is not None:
                    total += cur_e - cur_s  # type: ignore[operator]
                cur_s, cur_e = s, e
            else:
                cur_e = max(cur_e, e)
        if cur_e is not None:
            total += cur_e - cur_s  # type: ignore[operator]
        return total


__all__ = ["ENV_DIR", "MAX_BYTES", "CheckedCache", "CompileTimer", "cache_dir", "enable_compile_cache",
           "persistent_cache_bypassed", "read_sealed", "seal", "start_jax", "unseal", "warn_once", "write_sealed"]
