"""Monte-Carlo noise study of a sigmoid-model fit (the core of ``jaxlimb montecarlo``).

A disk (or ellipse) is rendered with the model itself on a pixel grid; the
pixels within ``annulus`` px of the limb of the *initial guess* are selected
(one fixed pixel set, so the Cramér--Rao bound applies to every realisation);
``n`` Gaussian noise realisations are fitted in batches by one compiled program
(:func:`_program`: noise drawn inside it, the solver's fit core under ``jax.lax.map`` --
the program of :func:`jaxlimb.fitting.fit_batch`; one by one for non-batchable solvers),
and the RMS error, bias and RMS/CRLB of every free parameter are reported.  The batches run
as chunks of the Monte-Carlo engine (:mod:`jaxlimb.analysis.montecarlo`): written to an
output directory and resumable.
"""

from __future__ import annotations

import math
import hashlib
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._jaxcache import CompileTimer
from ..errors import LimbInputError
from ..fitting import AbstractLimbSolver, LimbFit, LimbProblem, NormalLM, bucket_size, fit, pad_pixels
from ..fitting.fit import fit_core
from ..models import CIRCLE, ELLIPSE, CircleParams, EllipseParams, LimbModel, LimbParams
from .crlb import crlb
from .montecarlo import MonteCarloOptions, run_monte_carlo


@dataclass(frozen=True)
class ModelStudyOptions:
    """Settings of a model-only Monte-Carlo study (defaults: the core issue's benchmark problem)."""

    model: str = "circle"
    """``"circle"`` or ``"ellipse"``."""
    shape: tuple[int, int] = (400, 400)
    """Image size (rows, cols)."""
    radius: float = 150.0
    """Radius (circle) or semi-axis ``a`` (ellipse), px."""
    rho: float = 0.9
    """Axis ratio of the ellipse (held fixed in the fit)."""
    theta: float = 0.3
    """Orientation of the ellipse, rad."""
    k: float = 3.0
    ymax: float = 200.0
    ymin: float = 20.0
    sigma: float = 10.0
    """Gaussian noise, DN."""
    annulus: float = 6.0
    """Half-width of the selected band around the initial limb, px."""
    start_offset_px: float = 0.5
    """Distance of the initial centre from the truth (the radius starts off by the same)."""
    n: int = 1000
    seed: int = 0
    batch: int = 250
    """Realisations per vmapped batch."""
    fixed: tuple[str, ...] = field(default=())
    """Parameters held at their true values (``rho`` is always held for the ellipse)."""

    def __post_init__(self) -> None:
        if self.model not in ("circle", "ellipse"):
            raise LimbInputError(f"`model` must be 'circle' or 'ellipse', got {self.model!r}")
        from .._validate import POSITIVE, Range, number

        for name in ("radius", "k", "sigma", "annulus"):
            number(getattr(self, name), f"`{name}`", POSITIVE, error=LimbInputError)
        number(self.n, "`n`", Range(2, None), integer=True, error=LimbInputError)
        number(self.batch, "`batch`", Range(1, None), integer=True, error=LimbInputError)
        number(self.seed, "`seed`", Range(0, 2**32 - 1), integer=True, error=LimbInputError)
        names = (CIRCLE if self.model == "circle" else ELLIPSE).param_names
        unknown = sorted(set(self.fixed) - set(names))
        if unknown:
            raise LimbInputError(f"`fixed` (--fix) names unknown parameters {unknown}; the {self.model} model has {list(names)}")
        if not set(names) - set(self.fixed) - {"rho"}:
            raise LimbInputError(f"`fixed` (--fix) holds every parameter of the {self.model} model: nothing to estimate")


def estimated_nbytes(opt: ModelStudyOptions) -> float:
    """Peak memory (bytes) of :func:`run_model_study`: the pixel grid of :func:`model_problem`
    (about six float64 images) and the fit of one realisation (the compiled program maps over a
    batch one member at a time: data, residuals and the Jacobian of the ``2 pi radius x 2 annulus``
    band pixels, padded to the next bucket, x4 for the solver's temporaries)."""
    rows, cols = opt.shape
    n_pix = 1.5 * 2.0 * math.pi * opt.radius * 2.0 * opt.annulus
    n_par = 8 if opt.model == "ellipse" else 6
    return 8.0 * (6.0 * rows * cols + 4.0 * n_pix * (n_par + 6) + 2.0 * opt.batch * n_par)


def model_problem(opt: ModelStudyOptions) -> tuple[LimbModel, LimbParams, LimbParams, np.ndarray, tuple[str, ...]]:
    """The study's problem: ``(model, truth, init, coords, fixed)``.

    The body centre sits near the image centre (off the pixel grid by a fraction
    of a pixel); ``coords`` are the pixels within ``opt.annulus`` px of the
    initial guess's limb.
    """
    rows, cols = opt.shape
    r0, c0 = (rows - 1) / 2 + 0.3, (cols - 1) / 2 - 0.4
    d = opt.start_offset_px / np.sqrt(2.0)
    if opt.model == "circle":
        model: LimbModel = CIRCLE
        truth: LimbParams = CircleParams(r0, c0, opt.radius, opt.k, opt.ymax, opt.ymin)
        init: LimbParams = CircleParams(r0 + d, c0 - d, opt.radius + opt.start_offset_px, opt.k, opt.ymax, opt.ymin)
        fixed = tuple(opt.fixed)
    else:
        model = ELLIPSE
        truth = EllipseParams(r0, c0, opt.radius, opt.theta, opt.rho, opt.k, opt.ymax, opt.ymin)
        init = EllipseParams(r0 + d, c0 - d, opt.radius + opt.start_offset_px, opt.theta + 0.01, opt.rho, opt.k, opt.ymax, opt.ymin)
        fixed = tuple(sorted(set(opt.fixed) | {"rho"}))
    rr, cc = np.mgrid[0:rows, 0:cols]
    grid = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
    # band around the initial limb, in the model's own "distance" so it works for both
    ref = model.params_type.from_vector(init.to_vector())
    f_ref = np.asarray(model.intensity(ref.replace(k=1.0, ymax=1.0, ymin=0.0), jnp.asarray(grid)))
    # for k = 1, f = 1/(1+exp(d - R)) -> signed distance d - R = log(1/f - 1)
    with np.errstate(divide="ignore"):
        dist = np.log(np.clip(1.0 / np.clip(f_ref, 1e-300, 1.0) - 1.0, 1e-300, None))
    sel = np.abs(dist) <= opt.annulus
    return model, truth, init, grid[sel], fixed


def _program(model: LimbModel, free_idx: tuple[int, ...], solver: AbstractLimbSolver, sigma: float,
             max_steps: int = 256) -> Callable[..., LimbFit]:
    """The compiled study program: ``run(seeds (B,), theta0, coords, w, clean) -> LimbFit (B,)``.

    Each member draws its noise from ``jax.random.key(seed)`` inside the program and is fitted
    by the solver's fit core (``jax.lax.map``, as :func:`jaxlimb.fitting.fit_batch`'s ``"map"``
    strategy); the pixel set, the clean intensities and the start are arguments shared by
    every member (no per-member or per-batch copies of them).  With several local devices
    (e.g. ``XLA_FLAGS=--xla_force_host_platform_device_count=2`` on a 2-core CPU, which
    ``jaxlimb montecarlo`` sets), the seeds are split over them (``jax.shard_map``, each device
    fits its share one after another); the answer does not depend on the split.
    """

    def run(seeds: Array, theta0: Array, coords: Array, w: Array, clean: Array) -> LimbFit:
        def one(seed: Array) -> LimbFit:
            z = clean + sigma * jax.random.normal(jax.random.key(seed), clean.shape, clean.dtype)
            return fit_core(solver, LimbProblem(model, free_idx, True, theta0, coords, z, w), max_steps)

        return jax.lax.map(one, seeds)

    devices = jax.local_devices()
    if len(devices) == 1:
        return jax.jit(run)
    from jax.sharding import Mesh, PartitionSpec

    mesh, rep = Mesh(np.array(devices), ("batch",)), PartitionSpec()
    return jax.jit(jax.shard_map(run, mesh=mesh, in_specs=(PartitionSpec("batch"), rep, rep, rep, rep),
                                 out_specs=PartitionSpec("batch"), check_vma=False))


def _noisy(seeds: Array, clean: Array, sigma: float) -> Array:
    """The study's noisy intensities ``(B, N)`` (the same draws as :func:`_program`'s)."""
    def one(seed: Array) -> Array:
        return clean + sigma * jax.random.normal(jax.random.key(seed), clean.shape, clean.dtype)

    return jax.vmap(one)(seeds)


_noisy_jit = jax.jit(_noisy, static_argnums=2)


class _Problem(NamedTuple):
    model: LimbModel
    truth: LimbParams
    init: LimbParams
    coords: np.ndarray
    fixed: tuple[str, ...]


def _batch_trial(opt: ModelStudyOptions, solver: AbstractLimbSolver, prob: _Problem,
                 names: Sequence[str]) -> Callable[[np.ndarray, np.ndarray], dict[str, np.ndarray]]:
    """The engine's batched trial: ``trial(seeds, indices) -> {param: (b,), n_steps, ok}``."""
    model, coords = prob.model, prob.coords
    n = coords.shape[0]
    clean = np.asarray(model.intensity(prob.truth, jnp.asarray(coords)))
    c_p, clean_p, w_p = pad_pixels(coords, clean, np.ones(n), bucket_size(n))
    shared = [jnp.asarray(a) for a in (np.asarray(prob.init.to_vector()), c_p, w_p, clean_p)]
    width = -(-opt.batch // jax.local_device_count()) * jax.local_device_count()  # a multiple of the devices
    program = None
    if solver.jittable:  # compiled here, ahead of the trials (the caller times it apart)
        jitted = _program(model, model.free_indices(prob.fixed), solver, opt.sigma)
        program = jitted.lower(jax.ShapeDtypeStruct((width,), jnp.int64), *shared).compile()
    cols = [model.param_names.index(nm) for nm in names]

    def trial(seeds: np.ndarray, indices: np.ndarray) -> dict[str, np.ndarray]:
        del indices
        b = seeds.size
        if program is not None:
            full = np.concatenate([seeds, np.repeat(seeds[:1], width - b)]) if b < width else seeds
            res = program(jnp.asarray(full, dtype=jnp.int64), *shared)  # one shape: one compiled program
            vec, conv, nst = (np.asarray(x)[:b] for x in (res.params.to_vector(), res.converged, res.n_steps))
        else:
            z = np.asarray(_noisy_jit(jnp.asarray(seeds, dtype=jnp.int64), shared[3], opt.sigma))[:, :n]
            fits = [fit(model, coords, zi, prob.init, solver, fixed=prob.fixed, throw=False) for zi in z]
            vec = np.stack([np.asarray(f.params.to_vector()) for f in fits])
            conv = np.array([bool(f.converged) for f in fits])
            nst = np.array([int(f.n_steps) for f in fits])
        out = {nm: vec[:, c] for nm, c in zip(names, cols)}
        return {**out, "n_steps": nst.astype(float), "ok": conv.astype(float)}

    return trial


def study_name(opt: ModelStudyOptions, solver: AbstractLimbSolver) -> str:
    """The study's identity in an output directory's manifest (a resume must match it)."""
    d = {k: v for k, v in asdict(opt).items() if k not in ("n", "seed", "batch")}
    key = json.dumps({**d, "solver": solver.name}, sort_keys=True, default=list)
    return f"model-study-{hashlib.sha1(key.encode()).hexdigest()[:12]}"


def run_model_study(opt: ModelStudyOptions, solver: AbstractLimbSolver | None = None, progress: bool = False,
                    out_dir: str | None = None) -> dict[str, object]:
    """Run the study; returns the dictionary printed by ``jaxlimb montecarlo --json``.

    The realisations run in chunks of ``opt.batch`` through the Monte-Carlo engine
    (:func:`jaxlimb.analysis.montecarlo.run_monte_carlo`): realisation ``i`` draws its noise
    from ``jax.random.key(trial_seed(opt.seed, i))`` (independent of the batch size and of a
    resume); with ``out_dir`` each finished chunk is written there and a rerun with the same
    settings resumes.  ``compile_s`` is the time spent tracing and compiling the program (or
    loading it from the persistent cache), before the trials; ``fit_s`` the wall time of the fits
    alone and ``fit_cpu_s`` their CPU time (less sensitive to a loaded machine); ``wall_s``
    everything.
    """
    from .._validate import check_memory

    check_memory(estimated_nbytes(opt), f"a {opt.shape[0]}x{opt.shape[1]} study of radius {opt.radius:g} px")
    solver = NormalLM() if solver is None else solver
    t_start = time.perf_counter()
    prob = _Problem(*model_problem(opt))
    bound = crlb(prob.model, prob.coords, prob.truth, opt.sigma, fixed=prob.fixed)
    names = bound.free
    t0 = time.perf_counter()
    trial = _batch_trial(opt, solver, prob, names)
    build_s = time.perf_counter() - t0
    mc_opt = MonteCarloOptions(n_trials=opt.n, chunk_size=opt.batch, seed=opt.seed, out_dir=out_dir,
                               name=study_name(opt, solver), progress=progress, batched=True)
    with CompileTimer() as ct:  # non-jittable solvers (SciPy) compile their callables on first use
        t0, c0 = time.perf_counter(), time.process_time()
        res = run_monte_carlo(trial, mc_opt)
        loop_s, loop_cpu = time.perf_counter() - t0, time.process_time() - c0
    ok = res.ok
    tv = np.asarray(prob.truth.to_vector())
    truth = {nm: float(tv[prob.model.param_names.index(nm)]) for nm in names}
    stats = res.stats(truth=truth, keys=names)["params"]
    steps = res.values["n_steps"][ok]
    c = bound.std
    nan = float("nan")
    return {
        "status": "ok",
        "n": opt.n,
        "converged": int(ok.sum()),
        "wall_s": time.perf_counter() - t_start,
        "fit_s": loop_s - ct.seconds,
        "fit_cpu_s": loop_cpu,
        "compile_s": build_s + ct.seconds,
        "chunks_run": res.chunks_run,
        "chunks_resumed": res.chunks_skipped,
        "rms": {nm: stats[nm].get("rms", nan) for nm in names},
        "bias": {nm: stats[nm].get("bias", nan) for nm in names},
        "crlb": {nm: c[nm] for nm in names},
        "rms_over_crlb": {nm: stats[nm].get("rms", nan) / c[nm] for nm in names},
        "iterations": {"mean": float(steps.mean()) if ok.any() else None,
                       "max": int(steps.max()) if ok.any() else None},
        "n_pixels": int(prob.coords.shape[0]),
        "solver": solver.name,
        "options": asdict(opt),
        "fixed": list(prob.fixed),
    }


def study_table(result: dict[str, object], params: Sequence[str] | None = None) -> str:
    """A small text table of RMS, bias, CRLB and RMS/CRLB."""
    rms, bias, bound = result["rms"], result["bias"], result["crlb"]  # type: ignore[index]
    names = list(params or rms)  # type: ignore[arg-type]
    lines = [f"{'param':>8} {'RMS':>11} {'bias':>11} {'CRLB':>11} {'RMS/CRLB':>9}"]
    for n in names:
        lines.append(f"{n:>8} {rms[n]:11.5f} {bias[n]:11.5f} {bound[n]:11.5f} {rms[n] / bound[n]:9.3f}")  # type: ignore[index]
    return "\n".join(lines)
