"""Shared helpers of the benchmark scripts: environment record, JSON output, a cache of rendered frames."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"


def environment() -> dict[str, Any]:
    """Git SHA, versions and machine, recorded beside every benchmark result.  The SHA is marked ``-dirty`` when a file
    outside ``benchmarks/results`` differs from it (another benchmark's output is not the code that ran)."""
    import jax
    import numpy
    import optimistix
    import scipy

    try:
        sha = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True,
            cwd=Path(__file__).resolve().parent,
        ).stdout.strip()
        outside_results = ["--", ":/", ":(top,exclude)benchmarks/results"]
        dirty = bool(subprocess.run(["git", "status", "--porcelain", *outside_results], capture_output=True, text=True,
                                    cwd=Path(__file__).resolve().parent).stdout.strip())
    except (OSError, subprocess.CalledProcessError):
        sha, dirty = "unknown", False
    return {
        "git_sha": sha + ("-dirty" if dirty else ""),
        "python": sys.version.split()[0],
        "jax": jax.__version__,
        "optimistix": optimistix.__version__ if hasattr(optimistix, "__version__") else "unknown",
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "machine": platform.machine(),
        "cpu_count": os.cpu_count(),
        "jax_devices": [str(d) for d in jax.devices()],
    }


def process_environment(pycache: Path | None, **extra: str) -> dict[str, str]:
    """The environment of a timed process: Python's bytecode cached under ``pycache``, as an installed package has it.

    ``PYTHONDONTWRITEBYTECODE`` is dropped (a sandbox may set it; every process would then compile the package from
    source, while JAX's own bytecode was written when it was installed); ``pycache=None`` keeps the environment as it
    is.  The first process fills the cache for every module, JAX's included, so baselines and commands compare alike."""
    env = {**os.environ, **extra}
    if pycache is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def save(name: str, obj: dict[str, Any]) -> Path:
    """Write ``benchmarks/results/<name>.json`` atomically and return the path."""
    from jaxlimb._io import write_json_atomic

    path = RESULTS / f"{name}.json"
    write_json_atomic(path, obj)
    return path


def add_earth_frame_args(ap) -> None:  # type: ignore[no-untyped-def]
    """``--families --n --seed --cache``: the set of ``benchmarks/families.py``'s Earth frames a benchmark runs on."""
    from jaxlimb.render.independent import EARTH_FAMILIES

    ap.add_argument("--families", default=",".join(EARTH_FAMILIES))
    ap.add_argument("--n", type=int, default=6, help="frames per family (even: near, odd: far)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--cache", type=Path, default=None)


def cached(cache: Path | None, key: str, make):  # type: ignore[no-untyped-def]
    """``make()``, kept as ``cache/key`` (a pickle, written atomically) and read from there when present."""
    import pickle

    if cache is not None and (cache / key).exists():
        with open(cache / key, "rb") as fh:
            return pickle.load(fh)
    value = make()
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        tmp = cache / (key + ".tmp")
        with open(tmp, "wb") as fh:
            pickle.dump(value, fh)
        tmp.replace(cache / key)
    return value
