"""Monte-Carlo noise study of a limb-model fit (the core of ``jaxlimb montecarlo`` and ``jaxlimb compare``).

A :class:`~jaxlimb.analysis.problems.StudyProblem` (one pixel set, the model's truth, the start) is fitted
on ``n`` Gaussian noise realisations by one compiled program per solver (:func:`seeded_fits`: the noise is
drawn inside it from each realisation's seed, the solver's fit core runs under ``jax.lax.map`` -- the
program of :func:`jaxlimb.fitting.fit_batch` -- and the seeds are split over the local devices with
:func:`jaxlimb.analysis.sharding.per_device`); solvers that cannot be compiled (SciPy) fit one realisation
after another.  The RMS error, bias and RMS/CRLB of every free parameter are reported.  The batches run as
chunks of the Monte-Carlo engine (:mod:`jaxlimb.analysis.montecarlo`): written to an output directory and
resumable.  Realisation ``i`` draws its noise from ``jax.random.key(trial_seed(seed, i))``: every solver
sees the same realisations, whatever the batch size or the number of devices.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._jaxcache import CompileTimer
from ..fitting import AbstractLimbSolver, LimbFit, LimbProblem, NormalLM, bucket_size, fit, pad_pixels
from ..fitting.fit import fit_core
from .crlb import crlb
from .montecarlo import MonteCarloOptions, MonteCarloResult, run_monte_carlo
from .problems import (ModelStudyOptions, StudyProblem, estimated_nbytes, model_problem,
                       standard_problem)
from .sharding import per_device


def _noisy(seeds: Array, clean: Array, scale: Array) -> Array:
    def one(seed: Array) -> Array:
        return clean + scale * jax.random.normal(jax.random.key(seed), clean.shape, clean.dtype)

    return jax.vmap(one)(seeds)


_noisy_jit = jax.jit(_noisy)


def noisy_intensities(seeds: np.ndarray, clean: np.ndarray, scale: np.ndarray | float) -> np.ndarray:
    """The realisations of :func:`seeded_fits`: ``clean + scale * N(0, 1)`` drawn from ``jax.random.key(seed)``.

    Parameters
    ----------
    seeds : np.ndarray (B,) of int
        One seed per realisation (:func:`~jaxlimb.analysis.montecarlo.trial_seed`).
    clean : np.ndarray (N,)
        Noise-free intensities (DN).
    scale : np.ndarray (N,) or float
        Noise standard deviation (DN), per pixel or one for all.

    Returns
    -------
    np.ndarray (B, N)
        One noisy realisation per seed.
    """
    scale = np.broadcast_to(np.asarray(scale, float), np.shape(clean))
    return np.asarray(_noisy_jit(jnp.asarray(seeds, dtype=jnp.int64), jnp.asarray(clean), jnp.asarray(scale)))


@dataclass(frozen=True)
class _Padded:
    """A problem's pixels padded to their bucket: coordinates, clean intensities, weights, noise sigma per pixel."""

    coords: np.ndarray
    clean: np.ndarray
    w: np.ndarray
    scale: np.ndarray
    n: int


def _padded(problem: StudyProblem) -> _Padded:
    n = problem.coords.shape[0]
    w = np.ones(n) if problem.weights is None else np.asarray(problem.weights, float)
    c_p, clean_p, w_p = pad_pixels(problem.coords, problem.clean, w, bucket_size(n))
    _, scale_p, _ = pad_pixels(problem.coords, problem.noise_scale, w, bucket_size(n))
    return _Padded(c_p, clean_p, w_p, scale_p, n)


def _run_fn(problem: StudyProblem, solver: AbstractLimbSolver, max_steps: int) -> Callable[..., LimbFit]:
    model, free_idx = problem.model, problem.model.free_indices(problem.fixed)

    def run(seeds: Array, theta0: Array, coords: Array, w: Array, clean: Array, scale: Array) -> LimbFit:
        def one(seed: Array) -> LimbFit:
            z = clean + scale * jax.random.normal(jax.random.key(seed), clean.shape, clean.dtype)
            return fit_core(solver, LimbProblem(model, free_idx, True, theta0, coords, z, w), max_steps)

        return jax.lax.map(one, seeds)

    return run


@dataclass(frozen=True)
class SeededFits:
    """A compiled study program: ``fits(seeds) -> LimbFit`` for any number of seeds (run in blocks of ``width``)."""

    problem: StudyProblem
    solver: AbstractLimbSolver
    width: int
    program: Any
    shared: tuple[Any, ...]
    padded: _Padded
    max_steps: int = 256

    def __call__(self, seeds: np.ndarray) -> dict[str, np.ndarray]:
        """``{"params": (b, p), "converged", "n_steps", "result"}`` of the realisations of ``seeds``."""
        if self.program is None:
            return self._one_by_one(seeds)
        parts = []
        for lo in range(0, seeds.size, self.width):
            block = seeds[lo : lo + self.width]
            full = np.concatenate([block, np.repeat(block[:1], self.width - block.size)]) if block.size < self.width else block
            res = self.program(jax.device_put(full.astype(np.int64)), *self.shared)  # one shape: one program
            b = block.size
            parts.append({"params": np.asarray(res.params.to_vector())[:b], "converged": np.asarray(res.converged)[:b],
                          "n_steps": np.asarray(res.n_steps)[:b], "result": np.asarray(res.result._value)[:b]})
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def _one_by_one(self, seeds: np.ndarray) -> dict[str, np.ndarray]:
        """One :func:`~jaxlimb.fitting.fit` per seed, its realisation drawn just before (one compiled draw)."""
        p, pad = self.problem, self.padded
        fits = [fit(p.model, p.coords, noisy_intensities(s[None], pad.clean, pad.scale)[0, : pad.n], p.init, self.solver,
                    fixed=p.fixed, weights=p.weights, max_steps=self.max_steps, throw=False) for s in seeds]
        return {"params": np.stack([np.asarray(f.params.to_vector()) for f in fits]),
                "converged": np.array([bool(f.converged) for f in fits]),
                "n_steps": np.array([int(f.n_steps) for f in fits]),
                "result": np.array([int(np.asarray(f.result._value)) for f in fits])}


def seeded_fits(problem: StudyProblem, solver: AbstractLimbSolver, batch: int, max_steps: int = 256) -> SeededFits:
    """Compile the study program of ``problem`` for ``solver`` (module docstring).

    Parameters
    ----------
    problem : StudyProblem
        Pixels, truth, start and noise of the study.
    solver : AbstractLimbSolver
        The solver; a non-jittable one (SciPy) fits one realisation after another instead.
    batch : int
        Realisations per compiled call, rounded up to a multiple of the local devices.
    max_steps : int
        Iteration limit of each fit.

    Returns
    -------
    SeededFits
        ``fits(seeds) -> {"params" (b, p), "converged", "n_steps", "result"}``.
    """
    pad = _padded(problem)
    shared = tuple(jax.device_put(a) for a in (np.asarray(problem.init.to_vector()), pad.coords, pad.w, pad.clean,
                                               pad.scale))
    n_dev = jax.local_device_count()
    width = -(-batch // n_dev) * n_dev
    program = None
    if solver.jittable:
        seeds = jax.ShapeDtypeStruct((width,), jnp.int64)
        jitted = per_device(_run_fn(problem, solver, max_steps), (seeds, *shared), (True,) + (False,) * 5)
        program = jitted.lower(seeds, *shared).compile()
    return SeededFits(problem, solver, width, program, shared, pad, max_steps)


def _batch_trial(fits: SeededFits, names: Sequence[str]) -> Callable[[np.ndarray, np.ndarray], dict[str, np.ndarray]]:
    """The engine's batched trial: ``trial(seeds, indices) -> {param: (b,), n_steps, ok}``."""
    cols = [fits.problem.model.param_names.index(nm) for nm in names]

    def trial(seeds: np.ndarray, indices: np.ndarray) -> dict[str, np.ndarray]:
        del indices
        out = fits(seeds)
        vec = out["params"]
        return {**{nm: vec[:, c] for nm, c in zip(names, cols)}, "n_steps": out["n_steps"].astype(float),
                "ok": out["converged"].astype(float)}

    return trial


def study_name(opt: ModelStudyOptions, solver: AbstractLimbSolver) -> str:
    """The study's identity in an output directory's manifest (a resume must match it).

    Parameters
    ----------
    opt : ModelStudyOptions
        The study; ``n``, ``seed`` and ``batch`` are left out (the engine's manifest records them).
    solver : AbstractLimbSolver
        The solver, by its name.

    Returns
    -------
    str
        ``"model-study-"`` and 12 hex digits of a SHA-1 of the settings.
    """
    d = {k: v for k, v in asdict(opt).items() if k not in ("n", "seed", "batch")}
    key = json.dumps({**d, "solver": solver.name}, sort_keys=True, default=list)
    return f"model-study-{hashlib.sha1(key.encode()).hexdigest()[:12]}"


def problem_crlb(problem: StudyProblem) -> dict[str, float]:
    """The Cramér--Rao bound (1 sigma) of the free parameters at the truth, with the realisations' noise.

    With weights, the Fisher matrix is ``(J w/sigma)^T (J w/sigma)`` (pixel noise ``sigma / w``), as in
    :func:`~jaxlimb.analysis.crlb.crlb`.

    Parameters
    ----------
    problem : StudyProblem
        Model, truth, pixels, fixed parameters, noise ``sigma`` (DN) and optional weights.

    Returns
    -------
    dict of str to float
        1-sigma bound per free parameter, in the parameter's unit (px for centre and radius).
    """
    if problem.weights is None:
        return crlb(problem.model, problem.coords, problem.truth, problem.sigma, fixed=problem.fixed).std
    free_idx = list(problem.model.free_indices(problem.fixed))
    J = np.asarray(problem.model.jacobian(problem.truth, jnp.asarray(problem.coords)))[:, free_idx]
    Jw = J * (np.asarray(problem.weights, float) / problem.sigma)[:, None]
    cov = np.linalg.inv(Jw.T @ Jw)
    return {problem.free[i]: float(np.sqrt(cov[i, i])) for i in range(len(free_idx))}


def error_stats(values: np.ndarray, ok: np.ndarray, truth: float, bound: float) -> dict[str, float]:
    """RMS, bias and RMS/CRLB of the converged ``values`` about ``truth``.

    Parameters
    ----------
    values : np.ndarray (n,)
        Estimates of one parameter.
    ok : np.ndarray (n,) of bool
        Converged fits; non-finite values are dropped as well.
    truth : float
        The true value.
    bound : float
        Its Cramér--Rao 1-sigma bound.

    Returns
    -------
    dict
        ``rms``, ``bias``, ``rms_over_crlb`` (NaN when nothing converged) and the count ``n``.
    """
    e = values[ok & np.isfinite(values)] - truth
    if e.size == 0:
        return {"rms": float("nan"), "bias": float("nan"), "rms_over_crlb": float("nan"), "n": 0}
    rms = float(np.sqrt(np.mean(e * e)))
    return {"rms": rms, "bias": float(e.mean()), "rms_over_crlb": rms / bound, "n": int(e.size)}


def run_model_study(opt: ModelStudyOptions, solver: AbstractLimbSolver | None = None, progress: bool = False,
                    out_dir: str | None = None) -> dict[str, object]:
    """Run the study; returns the dictionary printed by ``jaxlimb montecarlo --json``.

    With ``out_dir`` each finished chunk is written there and a rerun with the same settings resumes.
    ``compile_s`` is the time spent tracing and compiling the program (or loading it from the persistent
    cache), before the trials; ``fit_s`` the wall time of the fits alone and ``fit_cpu_s`` their CPU time
    (less sensitive to a loaded machine); ``wall_s`` everything.

    Parameters
    ----------
    opt : ModelStudyOptions
        The study (:func:`~jaxlimb.analysis.problems.standard_problem`, ``n``, ``seed``, ``batch``).
    solver : AbstractLimbSolver, optional
        Default :class:`~jaxlimb.fitting.NormalLM`.
    progress : bool
        Show the engine's progress bar.
    out_dir : str, optional
        Directory of the chunk files (resumable); ``None`` keeps everything in memory.

    Returns
    -------
    dict
        ``rms``, ``bias``, ``crlb`` and ``rms_over_crlb`` per free parameter, ``converged`` of ``n``, iteration
        mean and max, the timings above, ``chunks_run``/``chunks_resumed``, ``n_pixels``, ``solver``, ``options``.

    Raises
    ------
    LimbInputError
        The study would not fit in the machine's memory.
    """
    from .._validate import check_memory

    check_memory(estimated_nbytes(opt), f"a {opt.shape[0]}x{opt.shape[1]} study of radius {opt.radius:g} px")
    solver = NormalLM() if solver is None else solver
    t_start = time.perf_counter()
    prob = standard_problem(opt)
    bound = problem_crlb(prob)
    names = prob.free
    t0 = time.perf_counter()
    trial = _batch_trial(seeded_fits(prob, solver, opt.batch), names)
    build_s = time.perf_counter() - t0
    mc_opt = MonteCarloOptions(n_trials=opt.n, chunk_size=opt.batch, seed=opt.seed, out_dir=out_dir,
                               name=study_name(opt, solver), progress=progress, batched=True)
    with CompileTimer() as ct:  # non-jittable solvers (SciPy) compile their callables on first use
        t0, c0 = time.perf_counter(), time.process_time()
        res = run_monte_carlo(trial, mc_opt)
        loop_s, loop_cpu = time.perf_counter() - t0, time.process_time() - c0
    accuracy = _accuracy(res, prob, bound)
    return {
        "status": "ok", "n": opt.n, "converged": int(res.ok.sum()), "wall_s": time.perf_counter() - t_start,
        "fit_s": loop_s - ct.seconds, "fit_cpu_s": loop_cpu, "compile_s": build_s + ct.seconds,
        "chunks_run": res.chunks_run, "chunks_resumed": res.chunks_skipped, **accuracy,
        "n_pixels": int(prob.coords.shape[0]), "solver": solver.name, "options": asdict(opt), "fixed": list(prob.fixed),
    }


def _accuracy(res: MonteCarloResult, prob: StudyProblem, bound: dict[str, float]) -> dict[str, object]:
    """``rms``, ``bias``, ``crlb``, ``rms_over_crlb`` and ``iterations`` of a finished study."""
    names = prob.free
    tv = np.asarray(prob.truth.to_vector())
    st = {nm: error_stats(res.values[nm], res.ok, float(tv[prob.model.param_names.index(nm)]), bound[nm]) for nm in names}
    steps = res.values["n_steps"][res.ok]
    return {
        "rms": {nm: st[nm]["rms"] for nm in names}, "bias": {nm: st[nm]["bias"] for nm in names},
        "crlb": dict(bound), "rms_over_crlb": {nm: st[nm]["rms_over_crlb"] for nm in names},
        "iterations": {"mean": float(steps.mean()) if res.ok.any() else None,
                       "max": int(steps.max()) if res.ok.any() else None},
    }


def study_table(result: dict[str, object], params: Sequence[str] | None = None) -> str:
    """A small text table of RMS, bias, CRLB and RMS/CRLB.

    Parameters
    ----------
    result : dict
        The output of :func:`run_model_study`.
    params : sequence of str, optional
        Rows to show; default every free parameter.

    Returns
    -------
    str
        A header line and one line per parameter.
    """
    rms, bias, bound = result["rms"], result["bias"], result["crlb"]  # type: ignore[index]
    names = list(params or rms)  # type: ignore[arg-type]
    lines = [f"{'param':>8} {'RMS':>11} {'bias':>11} {'CRLB':>11} {'RMS/CRLB':>9}"]
    for n in names:
        lines.append(f"{n:>8} {rms[n]:11.5f} {bias[n]:11.5f} {bound[n]:11.5f} {rms[n] / bound[n]:9.3f}")  # type: ignore[index]
    return "\n".join(lines)


__all__ = ["ModelStudyOptions", "SeededFits", "error_stats", "model_problem", "noisy_intensities", "problem_crlb",
           "run_model_study", "seeded_fits", "standard_problem", "study_name", "study_table"]
