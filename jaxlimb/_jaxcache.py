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

Concurrent processes.  JAX writes a cache entry with a plain ``write_bytes``; with a size
limit (``jax_compilation_cache_max_size``, here :data:`MAX_BYTES`) it takes a file lock
(``filelock``) around every read and write, so a reader never sees a half-written entry, and
evicts the least recently used entries beyond the limit.  An unreadable entry is a cache miss
(JAX recompiles; it never fails the computation).

:class:`CompileTimer` measures the wall time spent tracing, lowering and compiling (or loading
from the cache) inside a block, from JAX's monitoring time spans (the union of the spans, so
nested traces are not counted twice): the ``compile_s`` that the commands report apart from
the compute time.
"""

from __future__ import annotations

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
    except OSError:
        return None
    if not os.access(target, os.W_OK):
        return None
    jax.config.update("jax_compilation_cache_dir", str(target))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    jax.config.update("jax_compilation_cache_max_size", MAX_BYTES)  # LRU eviction + file lock
    return target


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


__all__ = ["ENV_DIR", "MAX_BYTES", "CompileTimer", "cache_dir", "enable_compile_cache", "start_jax"]
