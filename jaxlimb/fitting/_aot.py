"""Traced once per machine: the fit core exported (``jax.export``) beside the compilation cache.

JAX's persistent compilation cache (:mod:`jaxlimb._jaxcache`) stores compiled programs, but a
new process still traces and lowers every function before it can look the program up: for the
fit cores of ``locate`` (sigmoid and physical limb profiles) that is seconds per process.  When
the cache is on, :class:`ExportedCore` serialises the traced and lowered fit core
(``jax.export``) to ``<cache dir>/exported/<digest>.bin`` on first use, keyed by the jaxlimb
source, the JAX version, the solver, model, free set, step limit and the argument shapes, and
the executable compiled from it beside the other stored programs (:mod:`jaxlimb._programs`); a
later process loads that executable (no tracing, no lowering), or, without it, deserialises the
export (milliseconds) and compiles it (a persistent-cache hit).  The result is the same
program, so the same numbers.

Every file is sealed (:func:`jaxlimb._jaxcache.seal`: SHA-256 of the JAX/jaxlib versions and of the
bytes) and checked *before* it is deserialised: a damaged or foreign file never reaches
``jax.export.deserialize`` (which can abort the process) and never changes an answer; it is
deleted, the core is exported again, and one warning says so.  The folder is bounded like the stored
executables: the least recently used exports are deleted beyond :data:`jaxlimb._programs.MAX_BYTES`.

Anything unexpected (an output structure that cannot be rebuilt, a failed export or read) falls
back to plain ``jax.jit``; a tracer argument (a fit inside another ``jit``) always uses it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax

from .._programs import (
    array_signature,
    compile_and_store,
    evict_least_recent,
    guarded_call,
    hold_loaded,
    load_program,
    program_key,
    program_path,
)

_WHAT = "exported-program cache"


def _cache_dir() -> Path | None:
    d = jax.config.jax_compilation_cache_dir
    return Path(d) / "exported" if d else None


class ExportedCore:
    """``fn(*args) -> pytree`` of ``run``, loaded from / saved to the export cache per argument shapes.

    ``template(*args)`` builds, without tracing, an object with the output's tree structure.
    """

    def __init__(self, run: Callable[..., Any], ident: str, template: Callable[..., Any]) -> None:
        self._jit = jax.jit(run)
        self._run = run
        self._ident = ident
        self._template = template
        self._by_shape: dict[Any, Callable[..., Any]] = {}
        hold_loaded(self)

    def forget_loaded(self) -> None:
        """Drop the executables loaded per argument shapes (:func:`jaxlimb._programs.bound_compiled_programs`)."""
        self._by_shape.clear()

    def __call__(self, *args: Any) -> Any:
        if _cache_dir() is None or any(isinstance(a, jax.core.Tracer) for a in args):
            return self._jit(*args)
        sig = tuple(array_signature(a) for a in args)
        fn = self._by_shape.get(sig)
        if fn is None:
            fn = self._by_shape[sig] = self._build(sig, args)
        return fn(*args)

    def _build(self, sig: Any, args: tuple[Any, ...]) -> Callable[..., Any]:
        folder = _cache_dir()
        if folder is None:
            return self._jit
        try:
            treedef = jax.tree_util.tree_structure(self._template(*args))
            key = program_key("exported", self._ident, repr(sig))
            program = program_path("exported-executable", key)
            loaded = load_program(program, len(args)) if program is not None and program.exists() else None
            if loaded is not None:  # the executable of an earlier process: no export to read, nothing to lower
                return guarded_call(loaded[0], treedef, self._jit, program)
            path = folder / f"{key}.bin"
            exp = self._load(path) if path.exists() else None
            if exp is None:
                exp = self._export(path, treedef, args)
        except Exception:  # noqa: BLE001 - an optimisation: never a reason to fail a fit
            return self._jit
        if exp is None:
            return self._jit
        call = jax.jit(exp.call)
        with contextlib.suppress(Exception):
            flat = jax.tree_util.tree_structure(list(range(treedef.num_leaves)))
            return guarded_call(compile_and_store(program, call.lower(*args), lambda: flat), treedef, self._jit, program)
        return lambda *a: jax.tree_util.tree_unflatten(treedef, call(*a))

    @staticmethod
    def _load(path: Path) -> Any:
        from .._jaxcache import read_sealed, warn_once

        payload = read_sealed(path, _WHAT)  # checked before deserialising
        if payload is None:
            return None
        with contextlib.suppress(OSError):
            os.utime(path)  # least recently used: the modification time
        try:
            return jax.export.deserialize(bytearray(payload))
        except Exception:  # noqa: BLE001 - sealed by another jaxlimb that wrote something else: export again
            path.unlink(missing_ok=True)
            warn_once(_WHAT, f"{_WHAT} entry {path.name} cannot be deserialised: deleted and exported again")
            return None

    def _export(self, path: Path, treedef: Any, args: tuple[Any, ...]) -> Any:
        from .._jaxcache import write_sealed

        seen: dict[str, Any] = {}

        def flat(*a: Any) -> list[Any]:
            leaves, seen["treedef"] = jax.tree_util.tree_flatten(self._run(*a))
            return leaves

        exp = jax.export.export(jax.jit(flat))(*args)
        if seen.get("treedef") != treedef:  # the template does not rebuild this output: no export
            return None
        if write_sealed(path, bytes(exp.serialize()), _WHAT):
            evict_least_recent(path.parent)
        return exp


def stable_ident(*parts: Any) -> str | None:
    """A description of ``parts`` that is the same in every process, or ``None`` (no export).

    Functions count by module and qualified name and must not be closures (captured values
    would not be in the key); dataclass-like objects (models, solvers) field by field.
    """
    out = []
    for p in parts:
        s = _describe(p)
        if s is None:
            return None
        out.append(s)
    return "|".join(out)


def _describe(x: Any) -> str | None:
    import dataclasses

    if isinstance(x, type):
        return f"{x.__module__}.{x.__qualname__}"
    if callable(x) and hasattr(x, "__qualname__") and not dataclasses.is_dataclass(x):
        if getattr(x, "__closure__", None) or "<locals>" in x.__qualname__ or "<lambda>" in x.__qualname__:
            return None
        return f"{x.__module__}.{x.__qualname__}"
    if dataclasses.is_dataclass(x):
        fields = [_describe(getattr(x, f.name)) for f in dataclasses.fields(x)]
        if any(f is None for f in fields):
            return None
        return f"{type(x).__module__}.{type(x).__qualname__}({','.join(fields)})"  # type: ignore[arg-type]
    s = repr(x)
    return None if " at 0x" in s else s
