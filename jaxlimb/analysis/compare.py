r"""Every solver on the same noise realisations of one limb problem, timed interleaved and repeated.

The engine of ``jaxlimb compare`` (and ``jaxlimb montecarlo --solvers``).  Each solver gets its compiled study
program (:func:`jaxlimb.analysis.model_study.seeded_fits`: the noise of realisation ``i`` drawn inside it from
``trial_seed(seed, i)``, so every solver fits the very same data, on any number of devices).  Timing on a
shared machine: the realisations run in chunks, and for every chunk the solvers take turns in a rotating order
(chunk ``c`` starts with solver ``c mod S``), each chunk timed ``repeats`` times; a solver's ms/fit (wall and
CPU, the CPU time of every thread of the process) is the median over its chunks and repeats, with the
quartiles.  A burst of load then hits every solver alike instead of whichever ran during it.  Compilation is
timed apart (``compile_s``: tracing, compiling or loading from the persistent cache; the solvers' programs
compile side by side, one thread per local device).

Per solver: success rate, failures by reason (:class:`~jaxlimb.fitting.FitResult` names), iterations, ms/fit,
its ratio to the first solver's, bias, RMS and RMS/CRLB of every free parameter, and the largest difference
from the first solver's estimate on realisations both fitted (the same minimum: ~1e-8 px).
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from typing import Any

import jax
import numpy as np
from tqdm.auto import tqdm

from .._solver_names import SOLVER_NAMES
from ..errors import LimbInputError
from ..fitting import fit, result_names, solver_from_name
from .model_study import error_stats, noisy_intensities, problem_crlb, seeded_fits
from .figures import save_figure
from .montecarlo import trial_seed
from .problems import StudyProblem


@dataclass(frozen=True)
class CompareOptions:
    """Settings of :func:`compare_solvers`."""

    solvers: tuple[str, ...] = SOLVER_NAMES
    """Registered solver names (``jaxlimb.fitting.SOLVERS``), in table order; the first is the reference."""
    n: int = 1000
    """Realisations (the same for every solver)."""
    seed: int = 0
    chunk: int = 250
    """Realisations per timed call."""
    repeats: int = 1
    """Timings of each chunk per solver (the answers of the first are kept)."""
    max_steps: int = 256
    mode: str = "batch"
    """``"batch"``: the compiled Monte-Carlo program over the devices (:func:`~jaxlimb.analysis.model_study.seeded_fits`);
    ``"single"``: one :func:`jaxlimb.fitting.fit` call per realisation, as a pipeline fits one image (dispatch included)."""

    def __post_init__(self) -> None:
        from .._validate import Range, number

        unknown = [s for s in self.solvers if s not in SOLVER_NAMES]
        if unknown or not self.solvers or len(set(self.solvers)) != len(self.solvers):
            raise LimbInputError(f"`solvers` must be distinct names of {list(SOLVER_NAMES)}, got {list(self.solvers)}")
        number(self.n, "`n`", Range(2, 10_000_000), integer=True, error=LimbInputError)
        number(self.chunk, "`chunk`", Range(1, 100_000), integer=True, error=LimbInputError)
        number(self.repeats, "`repeats`", Range(1, 100), integer=True, error=LimbInputError)
        number(self.seed, "`seed`", Range(0, 2**32 - 1), integer=True, error=LimbInputError)
        if self.mode not in ("batch", "single"):
            raise LimbInputError(f"`mode` must be 'batch' or 'single', got {self.mode!r}")


def interleaved_timings(calls: dict[str, Callable[[int], Any]], n_blocks: int, repeats: int, progress: bool = False
                        ) -> tuple[dict[str, list[tuple[float, float]]], dict[str, list[Any]]]:
    """Time ``calls[name](block)`` for every block, the names taking turns in a rotating order, ``repeats`` times each.

    Block ``b`` starts with name ``b mod len(calls)``, so a burst of load on a shared machine hits every call alike.

    Parameters
    ----------
    calls : dict of str to callable
        ``calls[name](block_index)``: the work to time, already compiled.
    n_blocks : int
        Number of blocks (``0 .. n_blocks - 1``).
    repeats : int
        Timings of each block per name.
    progress : bool, optional
        Draw a bar of the blocks (tqdm, on stderr).

    Returns
    -------
    times : dict of str to list of (float, float)
        ``(wall_s, cpu_s)`` of every call, blocks in order and repeats within a block.
    results : dict of str to list
        The result of the first repeat of each block.
    """
    names = list(calls)
    times: dict[str, list[tuple[float, float]]] = {n: [] for n in names}
    out: dict[str, list[Any]] = {n: [] for n in names}
    for b in tqdm(range(n_blocks), desc="chunks", unit="chunk", disable=not progress):
        order = names[b % len(names):] + names[: b % len(names)]
        for r in range(repeats):
            for name in order:
                t0, c0 = time.perf_counter(), time.process_time()
                res = calls[name](b)
                times[name].append((time.perf_counter() - t0, time.process_time() - c0))
                if r == 0:
                    out[name].append(res)
    return times, out


def _timing_summary(times: list[tuple[float, float]], sizes: list[int], repeats: int) -> dict[str, float]:
    per = np.repeat(np.asarray(sizes, float), repeats)
    wall = 1e3 * np.array([t[0] for t in times]) / per
    cpu = 1e3 * np.array([t[1] for t in times]) / per
    q = lambda a, p: float(np.percentile(a, p))  # noqa: E731
    return {"ms_per_fit": q(wall, 50), "ms_per_fit_q25": q(wall, 25), "ms_per_fit_q75": q(wall, 75),
            "cpu_ms_per_fit": q(cpu, 50), "cpu_ms_per_fit_q25": q(cpu, 25), "cpu_ms_per_fit_q75": q(cpu, 75),
            "n_timings": int(wall.size)}


def _solver_row(name: str, res: dict[str, np.ndarray], problem: StudyProblem, bound: dict[str, float]) -> dict[str, Any]:
    ok = res["converged"]
    names = problem.model.param_names
    tv = np.asarray(problem.truth.to_vector())
    fails = Counter(r for r, good in zip(result_names(res["result"]), ok) if not good)
    steps = res["n_steps"][ok]
    params = {nm: error_stats(res["params"][:, names.index(nm)], ok, float(tv[names.index(nm)]), bound[nm])
              for nm in problem.free}
    return {"solver": name, "success_rate": float(ok.mean()), "n_ok": int(ok.sum()), "failures": dict(fails),
            "iterations_mean": float(steps.mean()) if steps.size else None,
            "iterations_median": float(np.median(steps)) if steps.size else None,
            "iterations_max": int(steps.max()) if steps.size else None, "params": params}


def _single_fits(problem: StudyProblem, solver: Any, max_steps: int) -> Callable[[np.ndarray], dict[str, np.ndarray]]:
    """``fits(z (b, n)) -> {"params", "converged", "n_steps", "result"}``: one :func:`~jaxlimb.fitting.fit` per row."""
    def fits(z: np.ndarray) -> dict[str, np.ndarray]:
        out = [fit(problem.model, problem.coords, zi, problem.init, solver, fixed=problem.fixed, weights=problem.weights,
                   max_steps=max_steps, throw=False) for zi in z]
        return {"params": np.stack([np.asarray(f.params.to_vector()) for f in out]),
                "converged": np.array([bool(f.converged) for f in out]),
                "n_steps": np.array([int(f.n_steps) for f in out]),
                "result": np.array([int(np.asarray(f.result._value)) for f in out])}

    return fits


def _build(problem: StudyProblem, opt: CompareOptions, blocks: list[np.ndarray]) -> tuple[dict[str, Any], dict[str, float]]:
    """Every solver's timed call ``call(block index)``, compiled first (``compile_s``; for SciPy its first fit).

    The batch programs compile side by side on one thread per local device (tracing holds the GIL, XLA's
    compilation does not): a solver's ``compile_s`` is its own elapsed time, shared with the others'.
    """
    noisy = None
    if opt.mode == "single":  # the realisations drawn before any timing (the batch programs draw their own)
        noisy = [noisy_intensities(b, problem.clean, problem.noise_scale) for b in blocks]

    def build(name: str) -> tuple[Callable[[int], Any], float]:
        solver = solver_from_name(name)
        t0 = time.perf_counter()
        if noisy is not None:
            single = _single_fits(problem, solver, opt.max_steps)
            single(noisy[0][:1])  # compiled (or loaded from the cache) before the timings
            call = lambda b, f=single, z=noisy: f(z[b])  # noqa: E731
        else:
            fits = seeded_fits(problem, solver, opt.chunk, opt.max_steps)
            if fits.program is None:  # SciPy: its callables compile on the first fit
                fits(blocks[0][:1])
            call = lambda b, f=fits: f(blocks[b])  # noqa: E731
        return call, time.perf_counter() - t0

    workers = 1 if opt.mode == "single" else max(1, min(jax.local_device_count(), os.cpu_count() or 1))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        built = dict(zip(opt.solvers, pool.map(build, opt.solvers)))
    return {n: built[n][0] for n in opt.solvers}, {n: built[n][1] for n in opt.solvers}


def compare_solvers(problem: StudyProblem, options: CompareOptions | None = None, progress: bool = False
                    ) -> dict[str, Any]:
    """Fit ``options.n`` realisations of ``problem`` with every solver of ``options`` (module docstring).

    Parameters
    ----------
    problem : StudyProblem
        The limb problem (:func:`jaxlimb.analysis.problems.standard_problem` or
        :func:`~jaxlimb.analysis.problems.model_problem`).
    options : CompareOptions, optional
        Solvers, number of realisations, seed, chunking and mode; default ``CompareOptions()``.
    progress : bool, optional
        Draw a bar of the timed chunks (tqdm, on stderr).

    Returns
    -------
    dict
        JSON-ready: ``rows`` (one per solver, in ``options.solvers`` order: success rate, failures, iterations,
        ms/fit wall and CPU with quartiles, ``compile_s``, per-parameter bias/RMS/RMS-over-CRLB,
        ``max_abs_diff_vs_first_px``), ``problem``, ``crlb``, ``options``, ``devices``, ``loadavg`` (1/5/15 min
        before and after), ``compile_wall_s`` (every solver compiled, :func:`_build`) and ``wall_s``.
    """
    opt = options or CompareOptions()
    t_start = time.perf_counter()
    load0 = os.getloadavg()
    bound = problem_crlb(problem)
    seeds = np.array([trial_seed(opt.seed, i) for i in range(opt.n)], dtype=np.int64)
    blocks = [seeds[i : i + opt.chunk] for i in range(0, opt.n, opt.chunk)]
    t_build = time.perf_counter()
    calls, compile_s = _build(problem, opt, blocks)
    compile_wall = time.perf_counter() - t_build
    times, outs = interleaved_timings(calls, len(blocks), opt.repeats, progress)
    rows = []
    sizes = [b.size for b in blocks]
    ref = None
    for name in opt.solvers:
        res = {k: np.concatenate([o[k] for o in outs[name]]) for k in outs[name][0]}
        row = _solver_row(name, res, problem, bound)
        row.update(_timing_summary(times[name], sizes, opt.repeats), compile_s=compile_s[name],
                   solver_class=solver_from_name(name).name)
        if ref is None:
            ref = res
        both = ref["converged"] & res["converged"]
        geo = [problem.model.param_names.index(nm) for nm in problem.free if nm in ("r0", "c0", "radius", "a", "xt")]
        row["max_abs_diff_vs_first_px"] = float(np.max(np.abs(res["params"][both][:, geo] - ref["params"][both][:, geo]))) \
            if both.any() and geo else None
        rows.append(row)
    first = rows[0]
    for row in rows:
        row["ms_over_first"] = row["ms_per_fit"] / first["ms_per_fit"]
        row["cpu_ms_over_first"] = row["cpu_ms_per_fit"] / first["cpu_ms_per_fit"]
    return {"status": "ok", "problem": {"label": problem.label, "model": problem.model.name, "free": list(problem.free),
                                        "fixed": list(problem.fixed), "n_pixels": int(problem.coords.shape[0]),
                                        "sigma": problem.sigma},
            "crlb": bound, "options": asdict(opt), "rows": rows, "devices": jax.local_device_count(),
            "loadavg": [*load0, *os.getloadavg()], "compile_wall_s": compile_wall,
            "wall_s": time.perf_counter() - t_start}


def _fmt(v: Any, spec: str, width: int) -> str:
    return f"{'-':>{width}}" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:{width}{spec}}"


def compare_table(result: dict[str, Any], params: Sequence[str] | None = None) -> str:
    """The comparison as a text table (ms/fit: median of the interleaved timings, wall and CPU; ``x REF``: ms/fit
    over the first solver's, measured in the same run; ``max it``: the slowest fit, which a vmapped chunk waits for).

    Parameters
    ----------
    result : dict
        The output of :func:`compare_solvers`.
    params : sequence of str, optional
        Parameters whose RMS/CRLB are shown; default the free geometric ones (``r0``, ``c0``, ``radius``, ``a``,
        ``xt``), else the first three free.

    Returns
    -------
    str
        One header line and one line per solver.
    """
    free = list(params or [p for p in result["problem"]["free"] if p in ("r0", "c0", "radius", "a", "xt")]
                or result["problem"]["free"][:3])
    ref = "x " + result["rows"][0]["solver"]  # ms/fit over the reference's (the first solver), in this run
    head = (f"{'solver':>15} {'ok':>6} {'iter':>6} {'max it':>6} {'ms/fit':>8} {'CPU ms':>8} {ref:>9} {'compile s':>9} "
            + " ".join(f"{'RMS/CRLB ' + p:>14}" for p in free) + f" {'max|d| px':>10}  failures")
    lines = [head]
    for r in result["rows"]:
        fails = ", ".join(f"{k} {v}" for k, v in r["failures"].items()) or "-"
        lines.append(f"{r['solver']:>15} {r['success_rate']:6.1%} {_fmt(r['iterations_mean'], '.1f', 6)} "
                     f"{_fmt(r['iterations_max'], 'd', 6)} {r['ms_per_fit']:8.2f} {r['cpu_ms_per_fit']:8.2f} "
                     f"{r['ms_over_first']:9.2f} {r['compile_s']:9.1f} "
                     + " ".join(_fmt(r["params"][p]["rms_over_crlb"], ".3f", 14) for p in free)
                     + f" {_fmt(r['max_abs_diff_vs_first_px'], '.1e', 10)}  {fails}")
    return "\n".join(lines)


def plot_compare(result: dict[str, Any], path: Any = None) -> Any:
    """ms/fit (median and quartiles of the interleaved timings, wall and CPU) and RMS/CRLB per solver.

    Parameters
    ----------
    result : dict
        The output of :func:`compare_solvers`.
    path : str or Path, optional
        Where to write the figure (:func:`~jaxlimb.analysis.figures.save_figure`); ``None`` writes nothing.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels sharing the solver axis.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    rows = result["rows"]
    names = [r["solver"] for r in rows]
    y = np.arange(len(rows))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(8.4, 0.42 * len(rows) + 1.4), sharey=True)
    for key, off, color in (("ms_per_fit", -0.15, "C0"), ("cpu_ms_per_fit", 0.15, "C1")):
        mid = np.array([r[key] for r in rows])
        err = np.array([[mid[i] - r[f"{key}_q25"], r[f"{key}_q75"] - mid[i]] for i, r in enumerate(rows)]).T
        ax1.errorbar(mid, y + off, xerr=err, fmt="o", color=color, ms=4, label="wall" if off < 0 else "CPU")
    ax1.set_xscale("log")
    ax1.set(xlabel="ms per fit (median, quartiles)", yticks=y, yticklabels=names)
    ax1.legend(fontsize=7)
    for j, p in enumerate(p for p in result["problem"]["free"] if p in ("r0", "c0", "radius", "a", "xt")):
        ax2.plot([r["params"][p]["rms_over_crlb"] for r in rows], y + 0.1 * (j - 1), "o", ms=4, label=p)
    ax2.axvline(1.0, color="k", lw=0.8, ls="--")
    ax2.set(xlabel="RMS / CRLB")
    ax2.legend(fontsize=7)
    fig.suptitle(f"{result['problem']['label']}: {result['options']['n']} realisations, {result['devices']} device(s)",
                 fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    return fig


__all__ = ["CompareOptions", "compare_solvers", "compare_table", "interleaved_timings", "plot_compare"]
