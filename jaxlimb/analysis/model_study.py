"""Monte-Carlo noise study of a sigmoid-model fit (the core of ``jaxlimb montecarlo``).

A disk (or ellipse) is rendered with the model itself on a pixel grid; the
pixels within ``annulus`` px of the limb of the *initial guess* are selected
(one fixed pixel set, so the Cramér--Rao bound applies to every realisation);
``n`` Gaussian noise realisations are fitted in batches with
:func:`jaxlimb.fitting.fit_batch` (or one by one for non-batchable solvers),
and the RMS error, bias and RMS/CRLB of every free parameter are reported.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from ..errors import LimbInputError
from ..fitting import AbstractLimbSolver, NormalLM, fit, fit_batch
from ..models import CIRCLE, ELLIPSE, CircleParams, EllipseParams, LimbModel, LimbParams
from .crlb import crlb


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


def estimated_nbytes(opt: ModelStudyOptions) -> float:
    """Peak memory (bytes) of :func:`run_model_study`: the pixel grid of :func:`model_problem`
    (about six float64 images) and one batch of fits (data, residuals and the Jacobian of the
    ``2 pi radius x 2 annulus`` band pixels, for every realisation of the batch)."""
    rows, cols = opt.shape
    n_pix = 2.0 * math.pi * opt.radius * 2.0 * opt.annulus
    n_par = 8 if opt.model == "ellipse" else 6
    return 8.0 * (6.0 * rows * cols + opt.batch * n_pix * (n_par + 6))


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


def run_model_study(opt: ModelStudyOptions, solver: AbstractLimbSolver | None = None,
                    progress: bool = False) -> dict[str, object]:
    """Run the study; returns the dictionary printed by ``jaxlimb montecarlo --json``."""
    from .._validate import check_memory

    check_memory(estimated_nbytes(opt), f"a {opt.shape[0]}x{opt.shape[1]} study of radius {opt.radius:g} px "
                 f"in batches of {opt.batch}")
    solver = NormalLM() if solver is None else solver
    model, truth, init, coords, fixed = model_problem(opt)
    clean = np.asarray(model.intensity(truth, jnp.asarray(coords)))
    bound = crlb(model, coords, truth, opt.sigma, fixed=fixed)
    rng = np.random.default_rng(opt.seed)
    names = bound.free
    idx = [model.param_names.index(n) for n in names]
    est = np.full((opt.n, len(names)), np.nan)
    steps = np.zeros(opt.n, dtype=int)
    ok = np.zeros(opt.n, dtype=bool)
    theta0 = np.asarray(init.to_vector())
    t_start = time.perf_counter()
    fit_s = 0.0
    bar = tqdm(total=opt.n, desc=f"montecarlo {opt.model} ({solver.name})", unit="fit", disable=not progress)
    done = 0
    while done < opt.n:
        b = min(opt.batch, opt.n - done) if solver.jittable else 1
        z = clean[None, :] + opt.sigma * rng.standard_normal((b, clean.size))
        t0 = time.perf_counter()
        if solver.jittable:
            # fixed batch size (pad the last batch) so every call reuses one compiled program
            zb = np.concatenate([z, np.repeat(z[:1], opt.batch - b, axis=0)]) if b < opt.batch else z
            init_b = model.params_type.from_vector(jnp.asarray(np.repeat(theta0[None], zb.shape[0], 0)))
            coords_b = np.broadcast_to(coords, (zb.shape[0], *coords.shape))
            res = fit_batch(model, coords_b, zb, init_b, solver, fixed=fixed)
            vec = np.asarray(res.params.to_vector())[:b]
            conv = np.asarray(res.converged)[:b]
            nst = np.asarray(res.n_steps)[:b]
        else:
            res1 = fit(model, coords, z[0], init, solver, fixed=fixed, throw=False)
            vec = np.asarray(res1.params.to_vector())[None]
            conv = np.asarray(res1.converged)[None]
            nst = np.asarray(res1.n_steps)[None]
        fit_s += time.perf_counter() - t0
        est[done : done + b] = vec[:, idx]
        ok[done : done + b] = conv
        steps[done : done + b] = nst
        done += b
        bar.update(b)
    bar.close()
    wall = time.perf_counter() - t_start
    tv = np.asarray(truth.to_vector())[idx]
    err = est[ok] - tv
    rms = np.sqrt(np.mean(err**2, axis=0)) if ok.any() else np.full(len(names), np.nan)
    bias = np.mean(err, axis=0) if ok.any() else np.full(len(names), np.nan)
    c = bound.std
    return {
        "n": opt.n,
        "converged": int(ok.sum()),
        "wall_s": wall,
        "fit_s": fit_s,
        "rms": {n: float(rms[i]) for i, n in enumerate(names)},
        "bias": {n: float(bias[i]) for i, n in enumerate(names)},
        "crlb": {n: c[n] for n in names},
        "rms_over_crlb": {n: float(rms[i] / c[n]) for i, n in enumerate(names)},
        "iterations": {"mean": float(steps[ok].mean()) if ok.any() else None,
                       "max": int(steps[ok].max()) if ok.any() else None},
        "n_pixels": int(coords.shape[0]),
        "solver": solver.name,
        "options": asdict(opt),
        "fixed": list(fixed),
    }


def study_table(result: dict[str, object], params: Sequence[str] | None = None) -> str:
    """A small text table of RMS, bias, CRLB and RMS/CRLB."""
    rms, bias, bound = result["rms"], result["bias"], result["crlb"]  # type: ignore[index]
    names = list(params or rms)  # type: ignore[arg-type]
    lines = [f"{'param':>8} {'RMS':>11} {'bias':>11} {'CRLB':>11} {'RMS/CRLB':>9}"]
    for n in names:
        lines.append(f"{n:>8} {rms[n]:11.5f} {bias[n]:11.5f} {bound[n]:11.5f} {rms[n] / bound[n]:9.3f}")  # type: ignore[index]
    return "\n".join(lines)
