r"""A Monte-Carlo engine for whole pipelines: seeded, chunked, resumable, streamed to disk.

A study is a user function run ``n_trials`` times:

* ``trial(seed, i) -> {name: number}`` (one trial: e.g. render a frame with noise seed
  ``seed``, run :func:`jaxlimb.pipeline.locate`, return the errors), or
* with ``batched=True``, ``trial(seeds, indices) -> {name: (b,) array}`` (a whole chunk at
  once: e.g. ``b`` noise realisations fitted by :func:`jaxlimb.fitting.fit_batch` or
  :func:`jaxlimb.analysis.sharding.sharded_fit_batch`).

Seeding.  Trial ``i`` of a study with seed ``s`` receives ``trial_seed(s, i)``, a 63-bit
integer from ``numpy.random.SeedSequence(s, spawn_key=(i,))``: statistically independent
streams, and trial ``i``'s result does not depend on the chunk size, on the order in which
chunks run, or on a resume.  Use it as ``np.random.default_rng(seed)`` or
``jax.random.key(seed)``.

Chunks and files.  Trials run in chunks of ``chunk_size``; each finished chunk is written
atomically (:func:`jaxlimb._io.atomic_path`: a temporary file renamed into place) to
``out_dir/chunk_NNNNNN.npz`` with the trial indices, seeds, a success flag, the error
name of failed trials and one column per returned key.  ``out_dir/manifest.json`` records
the study (name, seed, ``n_trials``, ``chunk_size``).  A rerun with the same settings
skips the chunks already on disk, so an interrupted run loses only the chunk in
progress; a chunk file that cannot be read back (truncated by a crash of the disk or the
machine, corrupted) is computed again with a :class:`ChunkRecomputedWarning` naming the file
(:func:`load_monte_carlo` raises a :class:`~jaxlimb.errors.ConfigError` naming it); a rerun with
*different* settings into the same directory is refused.
Failures: a trial that raises a :class:`~jaxlimb.errors.JaxlimbError` is recorded as
failed (``ok=False``, ``error=<check name>``, NaN values) -- "save on failure and filter
during analysis" (STYLE.md Sec. 7); any other exception stops the run.

Statistics (:meth:`MonteCarloResult.stats`): per key, over the successful trials, the
error ``value - truth`` (truth 0 when the trial returns errors itself): RMS, bias, sd,
percentiles, and RMS/CRLB when a bound is given; :meth:`MonteCarloResult.histogram` for
iteration counts.  Plots: :mod:`jaxlimb.analysis.figures` (error histograms with the CRLB Gaussian,
RMS against the CRLB).

Example::

    def trial(seed, i):                       # one rendered frame through the pipeline
        image, truth = render_body(moon_scene(60000.0, 30.0), cam, RenderOptions(), seed=seed)
        m = locate(image, cam, {"body": "moon"})
        return {"row": m.center_rc[0] - truth.center_rc[0], "iterations": m.iterations}

    res = run_monte_carlo(trial, MonteCarloOptions(n_trials=1000, chunk_size=50, out_dir="mc/run1"))
    res.stats(crlb={"row": 0.01})["params"]["row"]["rms_over_crlb"]

Scale-out: see :mod:`jaxlimb.analysis.sharding` (one batch over all local devices, and
the multi-host path).
"""

from __future__ import annotations

import json
import time
import warnings
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from .._io import atomic_open, write_json_atomic
from ..errors import ConfigError, JaxlimbError, LimbInputError
from .montecarlo_data import MonteCarloOptions, MonteCarloResult

_MANIFEST = "manifest.json"
_VERSION = 1


def trial_seed(seed: int, i: int) -> int:
    """The seed of trial ``i`` of a study seeded with ``seed`` (independent of chunking).

    Parameters
    ----------
    seed, i : int
        The study's seed and the trial index.

    Returns
    -------
    int
        63 bits, from ``numpy.random.SeedSequence(seed, spawn_key=(i,))``.
    """
    ss = np.random.SeedSequence(int(seed), spawn_key=(int(i),))
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))


def _chunk_path(out_dir: Path, c: int) -> Path:
    return out_dir / f"chunk_{c:06d}.npz"


def _manifest(opt: MonteCarloOptions) -> dict[str, Any]:
    return {"version": _VERSION, "name": opt.name, "seed": int(opt.seed), "n_trials": int(opt.n_trials),
            "chunk_size": int(opt.chunk_size), "batched": bool(opt.batched)}


def study_chunk_size(out_dir: str | Path) -> int | None:
    """The chunk size of the study already in ``out_dir`` (its manifest), or ``None`` when there is none.

    A resumed study must keep its chunks: a default chunk size that depends on the number of
    workers (:func:`jaxlimb.analysis.distributed.default_chunk`) would otherwise refuse to resume a
    study started with another number of workers.

    Parameters
    ----------
    out_dir : str or Path
        The study's directory.

    Returns
    -------
    int or None
        Trials per chunk recorded in ``out_dir/manifest.json``.
    """
    try:
        return int(json.loads((Path(out_dir) / _MANIFEST).read_text())["chunk_size"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _check_manifest(out_dir: Path, opt: MonteCarloOptions) -> None:
    from .._io import sweep_dead_temporaries

    sweep_dead_temporaries(out_dir)  # chunk temporaries of a killed run (a live writer's are kept)
    path = out_dir / _MANIFEST
    want = _manifest(opt)
    if path.exists():
        try:
            have = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise ConfigError(f"`out_dir` {str(out_dir)!r} has an unreadable {_MANIFEST}: {e}") from None
        diff = {k: (have.get(k), v) for k, v in want.items() if have.get(k) != v}
        if diff:
            raise ConfigError(
                f"`out_dir` {str(out_dir)!r} holds another study (differs in {diff}); use a new directory"
            )
    else:
        write_json_atomic(path, want)


def _columns(records: Sequence[Mapping[str, Any]], n: int) -> dict[str, np.ndarray]:
    keys: list[str] = []
    for r in records:
        for k in r:
            if k not in keys:
                keys.append(k)
    out = {}
    for k in keys:
        col = np.full(n, np.nan)
        for j, r in enumerate(records):
            if k in r and r[k] is not None:
                col[j] = float(r[k])
        out[k] = col
    return out


def _run_chunk(trial: Callable[..., Any], opt: MonteCarloOptions, c: int) -> dict[str, np.ndarray]:
    lo = c * opt.chunk_size
    idx = np.arange(lo, min(lo + opt.chunk_size, opt.n_trials))
    seeds = np.array([trial_seed(opt.seed, int(i)) for i in idx], dtype=np.int64)
    ok = np.ones(idx.size, dtype=bool)
    err = np.full(idx.size, "", dtype="<U40")
    if opt.batched:
        res = trial(seeds, idx)
        cols = {}
        for k, v in res.items():
            a = np.asarray(v, dtype=float)
            if a.shape != idx.shape:
                raise LimbInputError(f"batched trial returned {k!r} with shape {a.shape}, expected {idx.shape}")
            cols[k] = a
        if "ok" in cols:  # a batched trial may flag its own failures (e.g. fits that did not converge)
            ok = cols.pop("ok").astype(bool)
            err[~ok] = "trial_failed"
    else:
        records: list[Mapping[str, Any]] = []
        for j, (s, i) in enumerate(zip(seeds, idx)):
            try:
                r = trial(int(s), int(i))
            except JaxlimbError as e:
                ok[j], err[j] = False, e.check[:40]
                r = {}
            records.append(r)
        cols = _columns(records, idx.size)
        if "ok" in cols:
            flag = np.nan_to_num(cols.pop("ok"), nan=0.0).astype(bool)
            err[ok & ~flag] = "trial_failed"
            ok &= flag
    out = {"index": idx, "seed": seeds, "ok": ok, "error": err}
    for k, v in cols.items():
        if k in out:
            raise LimbInputError(f"trial key {k!r} is reserved (index, seed, ok, error)")
        out[f"v_{k}"] = v
    return out


class ChunkRecomputedWarning(UserWarning):
    """A chunk file of a resumed study was unreadable (truncated, corrupt) and is computed again."""


_CHUNK_KEYS = ("index", "seed", "ok", "error")


def _load_chunk(path: Path) -> dict[str, np.ndarray]:
    """Read one chunk file; an unreadable one (truncated, corrupt, not a chunk) is a :class:`ConfigError`."""
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as f:  # our handle: closed on any error
            data = {k: f[k] for k in f.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as e:
        raise ConfigError(f"chunk file {str(path)!r} is unreadable (truncated or corrupt: {type(e).__name__}: {e})") from None
    missing = [k for k in _CHUNK_KEYS if k not in data]
    if missing:
        raise ConfigError(f"chunk file {str(path)!r} is not a Monte-Carlo chunk (no {missing})")
    return data


def _resume_chunk(path: Path, expected: np.ndarray) -> dict[str, np.ndarray] | None:
    """A finished chunk from disk, or ``None`` (with a :class:`ChunkRecomputedWarning` naming the
    file) when it is unreadable or holds other trials: the caller computes it again."""
    try:
        data = _load_chunk(path)
    except ConfigError as e:
        warnings.warn(f"{e}; computing it again", ChunkRecomputedWarning, stacklevel=3)
        return None
    if not np.array_equal(data["index"], expected):
        warnings.warn(f"chunk file {str(path)!r} holds other trials than expected; computing it again",
                      ChunkRecomputedWarning, stacklevel=3)
        return None
    return data




def run_monte_carlo(trial: Callable[..., Mapping[str, Any]], options: MonteCarloOptions) -> MonteCarloResult:
    """Run (or resume) a Monte-Carlo study; see the module docstring.

    Parameters
    ----------
    trial : callable
        ``trial(seed, i) -> {key: number}``, or with ``options.batched``
        ``trial(seeds (b,), indices (b,)) -> {key: (b,) array}``; a key ``"ok"`` flags the trial's own failures.
    options : MonteCarloOptions
        Number of trials, chunk size, seed, output directory, sharding.

    Returns
    -------
    MonteCarloResult
        Every trial (of this process's shard and the chunks on disk), in trial order.

    Raises
    ------
    ConfigError
        ``out_dir`` holds a different study.
    LimbInputError
        A batched trial returned arrays of the wrong shape, or a reserved key.

    Examples
    --------
    Each trial returns the error of a mean of 100 draws of ``N(0, 1)`` (sd 0.1); 40 trials in chunks of 10:

    >>> import tempfile
    >>> def trial(seed, i):
    ...     return {"mean": np.random.default_rng(seed).normal(0.0, 1.0, 100).mean()}
    >>> with tempfile.TemporaryDirectory() as d:
    ...     opt = MonteCarloOptions(n_trials=40, chunk_size=10, out_dir=d, progress=False)
    ...     res = run_monte_carlo(trial, opt)
    ...     again = run_monte_carlo(trial, opt)  # a rerun reads the finished chunks back
    >>> res.chunks_run, again.chunks_skipped, int(res.ok.sum())
    (4, 4, 40)
    >>> round(res.stats(crlb={"mean": 0.1})["params"]["mean"]["rms_over_crlb"], 2)
    1.07
    """
    opt = options
    out_dir = Path(opt.out_dir) if opt.out_dir is not None else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        _check_manifest(out_dir, opt)
    t0 = time.perf_counter()
    chunks, run, skipped = _run_or_resume_chunks(trial, opt, out_dir)
    idx = np.concatenate([d["index"] for d in chunks])
    if opt.shard[1] == 1 and not np.array_equal(idx, np.arange(opt.n_trials)):
        raise ConfigError("chunk files do not cover the trials 0..n-1 in order: the output directory is corrupt")
    return _assemble(chunks, opt, time.perf_counter() - t0, run, skipped)


def _run_or_resume_chunks(trial: Callable[..., Mapping[str, Any]], opt: MonteCarloOptions,
                          out_dir: Path | None) -> tuple[list[dict[str, np.ndarray]], int, int]:
    """This process's chunks (read back from ``out_dir`` or run) and those other shards finished; with the
    numbers run and skipped."""
    chunks: list[dict[str, np.ndarray]] = []
    run = skipped = 0
    bar = tqdm(total=opt.n_trials, desc=opt.name, unit="trial", disable=not opt.progress or opt.shard[1] > 1)
    for c in range(opt.n_chunks):
        path = _chunk_path(out_dir, c) if out_dir is not None else None
        mine = c % opt.shard[1] == opt.shard[0]
        if not mine and (path is None or not path.exists()):
            continue  # another process's chunk, not finished yet
        lo = c * opt.chunk_size
        data = _resume_chunk(path, np.arange(lo, min(lo + opt.chunk_size, opt.n_trials))) \
            if path is not None and path.exists() else None
        if data is not None:
            skipped += 1
        else:
            data = _run_chunk(trial, opt, c)
            run += 1
            if path is not None:
                _write_chunk(path, data)
        chunks.append(data)
        bar.update(int(data["index"].size))
    bar.close()
    return chunks, run, skipped


def _assemble(chunks: list[dict[str, np.ndarray]], opt: MonteCarloOptions, wall_s: float, run: int,
              skipped: int) -> MonteCarloResult:
    """The chunks' columns concatenated in trial order (a key missing from a chunk: NaN there)."""
    keys: list[str] = []
    for d in chunks:
        keys += [k for k in d if k.startswith("v_") and k not in keys]
    return MonteCarloResult(
        values={k[2:]: np.concatenate([d.get(k, np.full(d["index"].size, np.nan)) for d in chunks]) for k in keys},
        ok=np.concatenate([d["ok"] for d in chunks]).astype(bool),
        error=np.concatenate([d["error"] for d in chunks]),
        seeds=np.concatenate([d["seed"] for d in chunks]),
        wall_s=wall_s, chunks_run=run, chunks_skipped=skipped, options=opt,
    )


def _write_chunk(path: Path, data: Mapping[str, np.ndarray]) -> None:
    with atomic_open(path, "wb") as fh:
        np.savez(fh, **data)


def prepare_study(options: MonteCarloOptions) -> list[int]:
    """Check (or write) ``options.out_dir``'s manifest and list the chunks still to compute.

    The first half of a distributed run (:mod:`jaxlimb.analysis.distributed`): each listed
    chunk is then one task, :func:`run_chunk_to_file`.  A chunk file that cannot be read back
    is listed again (with a :class:`ChunkRecomputedWarning` naming it).

    Parameters
    ----------
    options : MonteCarloOptions
        The study; ``out_dir`` is required.

    Returns
    -------
    list of int
        Indices of the chunks to compute.
    """
    if options.out_dir is None:
        raise LimbInputError("a distributed study needs `out_dir` (the chunks are its results)")
    out_dir = Path(options.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    _check_manifest(out_dir, options)
    todo = []
    for c in range(options.n_chunks):
        path = _chunk_path(out_dir, c)
        lo = c * options.chunk_size
        if not path.exists() or _resume_chunk(path, np.arange(lo, min(lo + options.chunk_size, options.n_trials))) is None:
            todo.append(c)
    return todo


def run_chunk_to_file(trial: Callable[..., Any], options: MonteCarloOptions, c: int) -> str:
    """Compute chunk ``c`` of the study and write it atomically to ``options.out_dir``; returns the path.

    The unit of work of a distributed run: a task killed before the rename leaves nothing
    (the temporary file is removed or ignored), a finished one is never computed again.

    Parameters
    ----------
    trial : callable
        As :func:`run_monte_carlo`; picklable for a Dask task.
    options : MonteCarloOptions
        The study; ``out_dir`` set.
    c : int
        Chunk index (trials ``c * chunk_size`` onward).

    Returns
    -------
    str
        Path of the chunk file written.
    """
    path = _chunk_path(Path(options.out_dir), c)  # type: ignore[arg-type]
    _write_chunk(path, _run_chunk(trial, options, c))
    return str(path)


def load_monte_carlo(out_dir: str | Path) -> MonteCarloResult:
    """Read a finished (or partial: only the finished chunks) study back from ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        The study's directory (its ``manifest.json`` and ``chunk_*.npz`` files).

    Returns
    -------
    MonteCarloResult
        The trials of the chunks on disk, in trial order (``wall_s`` 0).

    Raises
    ------
    ConfigError
        No readable manifest, no chunk file, or an unreadable chunk file.
    """
    out_dir = Path(out_dir)
    try:
        man = json.loads((out_dir / _MANIFEST).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ConfigError(f"no readable study in {str(out_dir)!r}: {e}") from None
    opt = MonteCarloOptions(n_trials=man["n_trials"], chunk_size=man["chunk_size"], seed=man["seed"],
                            out_dir=str(out_dir), name=man["name"], progress=False, batched=man["batched"])
    chunks = [_load_chunk(p) for p in sorted(out_dir.glob("chunk_*.npz"))]  # names sort in trial order
    if not chunks:
        raise ConfigError(f"no chunk files in {str(out_dir)!r}")
    return _assemble(chunks, opt, 0.0, 0, len(chunks))


def stats_json(result: MonteCarloResult, **kw: Any) -> dict[str, Any]:
    """``result.stats(**kw)`` plus the options and timing, JSON-ready.

    Parameters
    ----------
    result : MonteCarloResult
        The study.
    **kw
        Arguments of :meth:`MonteCarloResult.stats` (``truth``, ``crlb``, ``keys``, ``percentiles``).

    Returns
    -------
    dict
        The statistics with ``options`` (the study's settings) and ``wall_s``.
    """
    out = result.stats(**kw)
    out["options"] = asdict(result.options)
    out["wall_s"] = result.wall_s
    return out


__all__ = [
    "ChunkRecomputedWarning",
    "MonteCarloOptions",
    "MonteCarloResult",
    "load_monte_carlo",
    "prepare_study",
    "run_chunk_to_file",
    "run_monte_carlo",
    "stats_json",
    "study_chunk_size",
    "trial_seed",
]
