"""Compiled once per machine: jitted functions whose compiled executables are stored beside the compilation cache.

JAX's persistent compilation cache (:mod:`jaxlimb._jaxcache`) stores compiled programs, but every
new process still traces the Python function and lowers it to a module before it can look the
program up: for the profile's Jacobian columns and Fisher matrix that is most of a warm
``jaxlimb locate``.  :func:`stored_jit` wraps a function like ``jax.jit`` (or, with
``static_non_arrays``, like ``equinox.filter_jit``: only arrays are traced, every other leaf is a
compile-time constant); when the cache is on, the executable compiled for an argument signature is
serialised (``jax.experimental.serialize_executable``) to ``<cache dir>/programs/<digest>.bin`` and a
later process loads it (no tracing, no lowering).  The program is the one ``jax.jit`` compiles, so
the numbers are the same.

The key holds everything the traced program depends on: the jaxlimb sources and the JAX/jaxlib
versions (the digest of :func:`source_digest`), the function's module and name, the argument
signature (the classes and fields of the containers, the shape, dtype and weak type of each array,
the value of each constant leaf), the backend (platform, its version, the devices, ``XLA_FLAGS``,
the CPU's flags) and the trace-time settings registered with :func:`register_trace_setting`.  An
argument that cannot be described the same way in every process (an object printed with its
address, a closure) is never stored: the call is plain ``jax.jit``.  So is a call with tracer
arguments (inside another transformation).

Entries are sealed (:func:`jaxlimb._jaxcache.seal`) and checked before they are deserialised: a
damaged or foreign entry is deleted and compiled again (one warning).  Any other failure (a program
that cannot be serialised, an output that cannot be rebuilt) falls back to ``jax.jit``.

Every compiled program stays mapped in the process (its code and data are memory mappings), so a long
process that meets many array shapes -- ``locate`` over frames of many sizes, a test suite -- gathers
mappings until the kernel's limit (``vm.max_map_count``, 65 530 by default on Linux), where the next
compilation's ``mmap`` fails and XLA aborts the process.  :func:`bound_compiled_programs` (called by
``locate`` before every frame) drops every compiled program, JAX's and the loaded ones held here, once the
process holds more than half of that limit: the next call compiles again, or loads from the cache.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import gc
import hashlib
import os
import pickle
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

_WHAT = "compiled-program cache"
MAX_BYTES = 256 << 20
"""Size limit of the stored executables (least recently used entries are evicted beyond it)."""
_DIGEST: dict[str, str] = {}
_SETTINGS: dict[str, Callable[[], str]] = {}
_HOLDERS: weakref.WeakSet[Any] = weakref.WeakSet()


def hold_loaded(holder: Any) -> None:
    """Register an object whose ``forget_loaded()`` drops the executables it holds (:func:`bound_compiled_programs`)."""
    _HOLDERS.add(holder)


def mapped_regions() -> tuple[int, int] | None:
    """``(regions mapped by this process, the kernel's limit vm.max_map_count)``; ``None`` where ``/proc`` does not
    tell."""
    try:
        limit = int(Path("/proc/sys/vm/max_map_count").read_text())
        with open("/proc/self/maps", "rb") as fh:
            used = fh.read().count(b"\n")
    except (OSError, ValueError):
        return None
    return used, limit


def bound_compiled_programs() -> bool:
    """Drop every compiled program of the process once it maps more than half the kernel's limit of regions.

    Each XLA CPU executable holds memory mappings; past ``vm.max_map_count`` the next compilation cannot map its code
    and the process aborts (module docstring).  Below half the limit nothing happens (one read of ``/proc/self/maps``);
    above it JAX's caches (``jax.clear_caches``) and the executables loaded from this cache are dropped, so the next
    call of each function compiles again (or loads its stored program).  Returns whether they were dropped.
    """
    counts = mapped_regions()
    if counts is None or 2 * counts[0] < counts[1]:
        return False
    for holder in list(_HOLDERS):
        holder.forget_loaded()
    jax.clear_caches()
    gc.collect()
    return True


def register_trace_setting(name: str, current: Callable[[], str]) -> None:
    """Declare a module-level setting read while tracing (``current()`` describes its value): it joins the key
    of every stored program, so a program traced under another value is never loaded."""
    _SETTINGS[name] = current


def source_digest() -> str:
    """Digest of the jaxlimb sources and of the JAX/jaxlib versions (a changed package never loads an old entry)."""
    if "d" not in _DIGEST:
        import jaxlib

        h = hashlib.sha256(f"{jax.__version__}|{jaxlib.__version__}".encode())
        root = Path(__file__).resolve().parent
        for p in sorted(root.rglob("*.py")):
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
        _DIGEST["d"] = h.hexdigest()
    return _DIGEST["d"]


def _machine() -> str:
    """The backend and CPU an executable is compiled for."""
    if "m" not in _DIGEST:
        devices = jax.devices()
        flags = ""
        try:
            with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
                flags = next((ln for ln in fh if ln.startswith(("flags", "Features"))), "")
        except OSError:
            pass
        client = devices[0].client
        _DIGEST["m"] = (f"{client.platform}|{client.platform_version}|{[str(d) for d in devices]}|"
                        f"{os.environ.get('XLA_FLAGS', '')}|{hashlib.sha256(flags.encode()).hexdigest()}")
    return _DIGEST["m"]


def _folder() -> Path | None:
    d = jax.config.jax_compilation_cache_dir
    return Path(d) / "programs" if d else None


class _NoKey(Exception):
    """An argument that cannot be described the same way in every process."""


def _is_array(x: Any) -> bool:
    return isinstance(x, (jax.Array, np.ndarray, np.generic))


def array_signature(x: Any) -> str:
    """Shape, dtype and weak type of an array (a compiled program's argument type)."""
    a = jax.typeof(x) if isinstance(x, jax.Array) else None
    weak = "w" if a is not None and a.weak_type else ""
    return f"{tuple(np.shape(x))}{np.asarray(x).dtype if a is None else a.dtype}{weak}"


def _describe(x: Any, static_non_arrays: bool) -> str:
    """The part of the key of one argument: its containers by class and field, arrays by type, constants by value."""
    if _is_array(x):
        return f"A{array_signature(x)}"
    if x is None or isinstance(x, (bool, int, float, complex)):
        return f"{type(x).__name__}:{x!r}" if static_non_arrays or x is None else f"py:{type(x).__name__}"
    if isinstance(x, (tuple, list)):
        return f"{type(x).__name__}({','.join(_describe(v, static_non_arrays) for v in x)})"
    if isinstance(x, dict):
        return "dict(" + ",".join(f"{k!r}:{_describe(x[k], static_non_arrays)}" for k in sorted(x)) + ")"
    if isinstance(x, type):
        return f"T:{x.__module__}.{x.__qualname__}"
    if dataclasses.is_dataclass(x):
        inner = ",".join(f"{f.name}={_describe(getattr(x, f.name), static_non_arrays)}" for f in dataclasses.fields(x))
        return f"{type(x).__module__}.{type(x).__qualname__}({inner})"
    if callable(x) and hasattr(x, "__qualname__"):
        if getattr(x, "__closure__", None) or "<" in x.__qualname__:
            raise _NoKey
        return f"F:{x.__module__}.{x.__qualname__}"
    if isinstance(x, str):
        return repr(x)
    raise _NoKey


class StoredJit:
    """``jax.jit(fn)`` (``static_non_arrays``: ``equinox.filter_jit(fn)``) with executables stored per signature."""

    def __init__(self, fn: Callable[..., Any], static_non_arrays: bool = False) -> None:
        self._fn = fn
        self._ident: str | None
        self._static = static_non_arrays
        local = getattr(fn, "__closure__", None) or "<" in fn.__qualname__  # captured values are not in the key
        self._ident = None if local else f"{fn.__module__}.{fn.__qualname__}"
        if static_non_arrays:
            import equinox as eqx

            self._jit = eqx.filter_jit(fn)
        else:
            self._jit = jax.jit(fn)
        self._by_sig: dict[str, Callable[..., Any]] = {}
        functools.update_wrapper(self, fn)
        hold_loaded(self)

    def forget_loaded(self) -> None:
        """Drop the executables loaded or compiled per signature (:func:`bound_compiled_programs`)."""
        self._by_sig.clear()

    def __call__(self, *args: Any) -> Any:
        leaves, treedef = jax.tree_util.tree_flatten(args)
        if self._ident is None or _folder() is None or any(isinstance(v, jax.core.Tracer) for v in leaves):
            return self._jit(*args)
        try:
            sig = _describe(args, self._static)
        except _NoKey:
            return self._jit(*args)
        fn = self._by_sig.get(sig)
        if fn is None:
            fn = self._by_sig[sig] = self._build(sig, leaves, treedef)
        dynamic = [v for v in leaves if _is_array(v)] if self._static else leaves
        return fn(*dynamic)

    def _build(self, sig: str, leaves: list[Any], treedef: Any) -> Callable[..., Any]:
        mask = [_is_array(v) for v in leaves] if self._static else [True] * len(leaves)
        dynamic = [v for v, m in zip(leaves, mask) if m]
        try:
            path = program_path(self._ident, sig)
            loaded = load_program(path, len(dynamic)) if path is not None and path.exists() else None
            if loaded is None and path is not None:
                loaded = self._compile_and_store(path, leaves, mask, treedef)
        except Exception:  # noqa: BLE001 - an optimisation: never a reason to fail
            loaded = None
        if loaded is None:
            return lambda *dyn: self._jit(*_merge(treedef, leaves, mask, dyn))
        return guarded_call(loaded[0], loaded[1], lambda *dyn: self._jit(*_merge(treedef, leaves, mask, dyn)), path)

    def _compile_and_store(self, path: Path, leaves: list[Any], mask: list[bool], treedef: Any) -> Any:
        box: dict[str, Any] = {}

        def flat(*dyn: Any) -> list[Any]:
            out, box["tree"] = jax.tree_util.tree_flatten(self._fn(*_merge(treedef, leaves, mask, dyn)))
            return out

        lowered = jax.jit(flat).lower(*[v for v, m in zip(leaves, mask) if m])
        return compile_and_store(path, lowered, lambda: box["tree"]), box["tree"]


def guarded_call(compiled: Any, out_tree: Any, fallback: Callable[..., Any],
                 path: Path | None = None) -> Callable[..., Any]:
    """``f(*args)``: the stored executable ``compiled`` on ``args``, its flat results rebuilt as ``out_tree``;
    ``fallback(*args)`` (plain ``jit``) for arguments the executable was not made for (another device).

    The first call waits for its results: a stored executable can load and yet lack one of its functions, failing
    only when it runs (``NOT_FOUND: Function wrapped_broadcast not found``, seen on a cache that benchmark runs
    had filled).  Such an entry is deleted (``path``), one warning says so, and ``fallback`` answers from
    then on: a stored program is an optimisation, never a failure.

    Parameters
    ----------
    compiled : a loaded or compiled executable of flat array arguments returning a flat list.
    out_tree : the tree structure of the results.
    fallback : the function's ``jit``, called with the same arguments.
    path : the executable's entry on disk, if any.

    Returns
    -------
    The function of the arguments.
    """
    state = {"checked": False, "broken": False}

    def call(*args: Any) -> Any:
        if state["broken"]:
            return fallback(*args)
        try:
            out = compiled(*args)
            if not state["checked"]:
                jax.block_until_ready(out)
                state["checked"] = True
        except (TypeError, ValueError):
            return fallback(*args)
        except jax.errors.JaxRuntimeError as e:
            if "NOT_FOUND" not in str(e):
                raise
            from ._jaxcache import warn_once

            state["broken"] = True
            if path is not None:
                path.unlink(missing_ok=True)
            warn_once(_WHAT + " function", f"a stored executable{f' ({path.name})' if path is not None else ''} "
                      f"cannot run ({str(e).splitlines()[0][:120]}): deleted, compiled again")
            return fallback(*args)
        return jax.tree_util.tree_unflatten(out_tree, out)

    return call


def _merge(treedef: Any, leaves: list[Any], mask: list[bool], dyn: tuple[Any, ...]) -> tuple[Any, ...]:
    it = iter(dyn)
    return jax.tree_util.tree_unflatten(treedef, [next(it) if m else v for v, m in zip(leaves, mask)])


def program_key(*parts: str) -> str:
    """A key of ``parts`` with the sources, the versions, the machine, the trace-time settings
    (:func:`register_trace_setting`) and the float64 switch."""
    settings = "|".join(f"{k}={_SETTINGS[k]()}" for k in sorted(_SETTINGS))
    text = "|".join([source_digest(), _machine(), settings, str(jax.config.jax_enable_x64), *parts])
    return hashlib.sha256(text.encode()).hexdigest()[:40]


def program_path(*parts: str) -> Path | None:
    """Where the executable described by ``parts`` is stored (:func:`program_key`); ``None``: the cache is off."""
    folder = _folder()
    return None if folder is None else folder / f"{program_key(*parts)}.bin"


def compile_and_store(path: Path | None, lowered: Any, out_tree: Callable[[], Any]) -> Any:
    """``lowered.compile()``, its executable stored at ``path`` (:func:`load_program` reads it) with the structure
    ``out_tree()`` of the results it stands for (``lowered``: a function of flat array arguments returning a flat
    list).  Compiled apart from JAX's persistent cache: an executable loaded from that cache serialises without
    its functions (``NOT_FOUND: Function ... not found`` when the copy runs), one compiled here does not.  Nothing
    is stored when the structure cannot be rebuilt from a file."""
    from jax.experimental.serialize_executable import serialize

    from ._jaxcache import persistent_cache_bypassed, write_sealed

    if path is None:
        return lowered.compile()
    with persistent_cache_bypassed():
        compiled = lowered.compile()
    tree = out_tree()
    shape = pickle.dumps(jax.tree_util.tree_unflatten(tree, list(range(tree.num_leaves))))
    if jax.tree_util.tree_structure(pickle.loads(shape)) == tree:
        payload, _, _ = serialize(compiled)
        if write_sealed(path, pickle.dumps((payload, shape, tree.num_leaves)), _WHAT):
            evict_least_recent(path.parent)
    return compiled


def evict_least_recent(folder: Path) -> None:
    """Delete the least recently used ``*.bin`` entries of ``folder`` (modification time, touched on every load)
    beyond :data:`MAX_BYTES`, down to 90 % of it: each new version of the sources stores its own.

    Parameters
    ----------
    folder : Path
        A folder of sealed entries (stored executables, exported fit cores).
    """
    entries = []
    for p in folder.glob("*.bin"):
        with contextlib.suppress(OSError):
            st = p.stat()
            entries.append((st.st_mtime_ns, st.st_size, p))
    total = sum(size for _, size, _ in entries)
    for _, size, p in sorted(entries):
        if total <= MAX_BYTES * 9 // 10:
            break
        with contextlib.suppress(OSError):
            p.unlink()
        total -= size


def _lapack_ready() -> None:
    """Register jaxlib's CPU LAPACK kernels, as lowering a linear-algebra call does: an executable calling them,
    loaded in a process that has lowered none, would otherwise call an unregistered target (a crash)."""
    from jaxlib import lapack

    lapack.prepare_lapack_call("potrf_ffi", np.dtype(np.float64))


def load_program(path: Path, n_in: int) -> tuple[Any, Any] | None:
    """``(compiled, out_tree)`` stored by :func:`compile_and_store` for ``n_in`` array arguments, or ``None``
    (missing; a damaged or foreign entry is deleted, one warning)."""
    from jax.experimental.serialize_executable import deserialize_and_load

    from ._jaxcache import read_sealed, warn_once

    payload = read_sealed(path, _WHAT)  # checked before deserialising
    if payload is None:
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # least recently used: the modification time
    try:
        _lapack_ready()
        exe, shape, n_out = pickle.loads(payload)
        in_tree = jax.tree_util.tree_structure(((0,) * n_in, {}))
        out_tree = jax.tree_util.tree_structure(pickle.loads(shape))
        flat_out = jax.tree_util.tree_structure(list(range(n_out)))
        return deserialize_and_load(exe, in_tree, flat_out), out_tree
    except Exception:  # noqa: BLE001 - sealed by another jaxlimb that wrote something else: compile again
        path.unlink(missing_ok=True)
        warn_once(_WHAT, f"{_WHAT} entry {path.name} cannot be loaded: deleted and compiled again")
        return None


def stored_jit(fn: Callable[..., Any] | None = None, *, static_non_arrays: bool = False) -> Any:
    """Decorator: :class:`StoredJit` of ``fn`` (module docstring); ``@stored_jit`` or
    ``@stored_jit(static_non_arrays=True)``."""
    if fn is None:
        return lambda f: StoredJit(f, static_non_arrays)
    return StoredJit(fn, static_non_arrays)


__all__ = ["MAX_BYTES", "StoredJit", "array_signature", "bound_compiled_programs", "compile_and_store",
           "evict_least_recent", "guarded_call", "hold_loaded", "load_program", "mapped_regions", "program_key",
           "program_path", "register_trace_setting", "source_digest", "stored_jit"]
