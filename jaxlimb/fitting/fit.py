r"""One entry point for fitting a sigmoid limb model: :func:`fit`, and :func:`fit_batch` for many.

Both take the model, the pixel coordinates and intensities, an initial guess
(a parameter container), a solver *object* and the names of the parameters to
hold fixed (the paper's Table 1 fixes ``k``, ``ymax``, ``ymin``: an
:math:`n \times 3` Jacobian).  They return a :class:`LimbFit` with the
estimate, the covariance :math:`\hat\sigma^2 (J^\top J)^{-1}` over the free
parameters (:math:`\hat\sigma^2 = \sum r_i^2 / (n - q)`), the residual RMS, the
number of iterations and a :class:`~jaxlimb.fitting.solvers.FitResult`.

No recompilation.  Pixel sets are padded to a *bucket* size (see
:func:`bucket_size`) with zero-weight copies of a real pixel, so images whose
pixel counts fall in the same bucket reuse one compiled program, and padded
pixels contribute exactly nothing (no NaN).  :func:`compile_count` counts the
traces, for tests.

Precision.  Run in float64 (``jax.config.update("jax_enable_x64", True)``);
in float32 the default tolerances sit below the arithmetic precision and a fit
can report success while its centre is off by ~1e-3 px from rounding alone.
:func:`fit` warns on float32.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..errors import ConvergenceError, LimbInputError
from ..models import LimbModel, LimbParams
from ._aot import ExportedCore, stable_ident
from .pixels import bucket_size, pad_pixels, validate_inputs
from .problem import AbstractLimbSolver, FitResult, LimbProblem
from .solvers import NormalLM


class PrecisionWarning(UserWarning):
    """Estimation attempted without 64-bit floats."""


class LimbFit(eqx.Module):
    """The result of a limb fit (fields may carry a leading batch axis from :func:`fit_batch`).

    Attributes
    ----------
    params : the estimate, all parameters (fixed ones as given).
    free : names of the estimated parameters, in covariance order (static).
    covariance : :math:`\\hat\\sigma^2 (J^\\top J)^{-1}` over ``free``, ``(q, q)``.
    sigma2 : residual variance estimate :math:`\\sum r^2 / (n - q)`.
    rms : residual RMS :math:`\\sqrt{\\sum r^2 / n}`.
    n_pixels : number of (unpadded) pixels used.
    n_steps : solver iterations.
    result : a :class:`FitResult`; ``FitResult.successful`` only if converged.
    solver : name of the solver (static).
    """

    params: LimbParams
    free: tuple[str, ...] = eqx.field(static=True)
    covariance: Float[Array, "... q q"]
    sigma2: Float[Array, "..."]
    rms: Float[Array, "..."]
    n_pixels: Int[Array, "..."]
    n_steps: Int[Array, "..."]
    result: FitResult
    solver: str = eqx.field(static=True)

    @property
    def converged(self) -> Array:
        """Boolean (array): the solver reported success.

        On host values compared in NumPy: an eager ``==`` of two JAX arrays is one more compiled
        program for every process that asks.
        """
        value = self.result._value
        if isinstance(value, jax.core.Tracer):
            return self.result == FitResult.successful
        return np.asarray(value) == np.asarray(FitResult.successful._value)

    @property
    def std(self) -> dict[str, Array]:
        """1-sigma uncertainty of each free parameter."""
        d = jnp.sqrt(jnp.diagonal(self.covariance, axis1=-2, axis2=-1))
        return {n: d[..., i] for i, n in enumerate(self.free)}

    def covariance_dict(self) -> dict[str, dict[str, float]]:
        """The covariance as nested ``{row: {col: value}}`` (scalar fits only).

        Returns
        -------
        dict of str to dict of str to float
            ``cov[a][b]`` for the free parameters ``a``, ``b`` (units: theirs, e.g. px^2 for the centre).
        """
        c = np.asarray(self.covariance)
        return {a: {b: float(c[i, j]) for j, b in enumerate(self.free)} for i, a in enumerate(self.free)}

    @property
    def message(self) -> str:
        return _message(self.result)


def _message(result: FitResult) -> str:
    return FitResult[result] if np.ndim(result._value) == 0 else "batched result"


def _check_precision() -> None:
    if not jax.config.jax_enable_x64:
        warnings.warn(
            "jaxlimb fits need float64: call jax.config.update('jax_enable_x64', True) first. "
            "In float32 a fit may report success while its tolerances sit below the precision.",
            PrecisionWarning,
            stacklevel=3,
        )


# ============================================================================ core
_TRACES = {"fit": 0}


def compile_count() -> int:
    """How many times the jitted fit core has been traced (== compiled) in this process.

    Returns
    -------
    int
        The count since the process started.
    """
    return _TRACES["fit"]


def _core(solver: AbstractLimbSolver, problem: LimbProblem, max_steps: int) -> LimbFit:
    y0 = problem.theta0[jnp.asarray(problem.free_idx)]
    if isinstance(solver, NormalLM):  # reuse its normal equations at the solution
        y, n_steps, result, normal = solver.solve_normal(problem, y0, max_steps)
        return _make_fit(problem, y, n_steps, result, solver.name, normal)
    y, n_steps, result = solver.solve(problem, y0, max_steps)
    return _make_fit(problem, y, n_steps, result, solver.name)


def fit_core(solver: AbstractLimbSolver, problem: LimbProblem, max_steps: int = 256) -> LimbFit:
    """The un-jitted single-fit core of :func:`fit`: for programs that build their problems inside
    ``jax.jit`` (e.g. the Monte-Carlo study, :func:`jaxlimb.analysis.model_study._program`).

    Parameters
    ----------
    solver : AbstractLimbSolver
        A jittable solver.
    problem : LimbProblem
        The problem, pixels already padded (:func:`pad_pixels`).
    max_steps : int
        Iteration limit.

    Returns
    -------
    LimbFit
        The fit; never raises on non-convergence (check ``result``).
    """
    return _core(solver, problem, max_steps)


def _make_fit(problem: LimbProblem, y: Array, n_steps: Array, result: FitResult, solver_name: str,
              normal: tuple[Array, Array, Array] | None = None) -> LimbFit:
    """Assemble the :class:`LimbFit`: covariance, residual statistics, full parameters."""
    jtj, _, rss = problem.normal_equations(y) if normal is None else normal
    n = jnp.sum(problem.w > 0)
    q = problem.n_free
    sigma2 = rss / (n - q)
    theta = problem.theta0.at[jnp.asarray(problem.free_idx)].set(y)
    model = problem.model
    return LimbFit(
        params=model.params_type.from_vector(theta),
        free=tuple(model.param_names[i] for i in problem.free_idx),
        covariance=sigma2 * jnp.linalg.inv(jtj),
        sigma2=sigma2,
        rms=jnp.sqrt(rss / n),
        n_pixels=n,
        n_steps=jnp.asarray(n_steps),
        result=result,
        solver=solver_name,
    )


def _to_device(a: Any) -> Array:
    """``jnp.asarray`` for host (NumPy) data without compiling an identity program per shape."""
    return jax.device_put(a) if isinstance(a, np.ndarray) else jnp.asarray(a)


def _traced_core(solver, problem, max_steps):  # type: ignore[no-untyped-def]
    _TRACES["fit"] += 1
    return _core(solver, problem, max_steps)


_JITTED: dict[Any, Any] = {}
_core_filter_jit = eqx.filter_jit(_traced_core)


def _core_jit(solver: AbstractLimbSolver, problem: LimbProblem, max_steps: int) -> LimbFit:
    """The jitted single-fit core, one ``jax.jit`` per (solver, model, free set, analytic, max_steps).

    Cheaper to call than ``eqx.filter_jit`` (no pytree partitioning of the static
    configuration at every call): the dispatch overhead matters for 3-ms fits.
    """
    masked = problem.mask is not None
    key = (solver, problem.model, problem.free_idx, problem.analytic, "masked" if masked else max_steps)
    try:
        fn = _JITTED.get(key)
    except TypeError:  # a solver holding arrays (e.g. optimistix's trust-region checks): not hashable
        return _core_filter_jit(solver, problem, max_steps)
    if fn is None:
        model, free_idx, analytic = problem.model, problem.free_idx, problem.analytic

        def run(theta0: Array, coords: Array, z: Array, w: Array, *held: Array) -> LimbFit:
            mask, steps = held if held else (None, max_steps)  # masked: the mask and the step limit are data
            return _traced_core(solver, LimbProblem(model, free_idx, analytic, theta0, coords, z, w, mask), steps)

        ident = stable_ident(solver, model, free_idx, analytic, "masked" if masked else max_steps)
        fn = _JITTED[key] = jax.jit(run) if ident is None else ExportedCore(run, ident, _template(model, free_idx, solver.name))
    if masked:
        return fn(*problem.args, problem.mask, _to_device(np.asarray(max_steps, dtype=np.int64)))
    return fn(*problem.args)


def _template(model: LimbModel, free_idx: tuple[int, ...], solver_name: str) -> Any:
    """``(*args) -> LimbFit`` of placeholders: the output structure of the fit core, without tracing."""
    def template(*args: Any) -> LimbFit:
        del args
        q, zero = len(free_idx), np.zeros(())
        return LimbFit(params=model.params_type.from_vector(np.zeros(len(model.param_names))),
                       free=tuple(model.param_names[i] for i in free_idx), covariance=np.zeros((q, q)),
                       sigma2=zero, rms=zero, n_pixels=zero, n_steps=zero, result=FitResult.successful,
                       solver=solver_name)

    return template
def batch_core(solver: AbstractLimbSolver, problem: LimbProblem, max_steps: int) -> LimbFit:
    """Fit every member of a batched ``problem`` one after another (``jax.lax.map``); un-jitted.

    The building block of :func:`fit_batch` (``strategy="map"``) and of
    :func:`jaxlimb.analysis.sharding.sharded_fit_batch` (one call per device).

    Parameters
    ----------
    solver : AbstractLimbSolver
        A jittable solver.
    problem : LimbProblem
        A batched problem: every array field has a leading batch axis (:func:`batch_problem`).
    max_steps : int
        Iteration limit of each member.

    Returns
    -------
    LimbFit
        The fits, fields with a leading batch axis ``(B, ...)``.
    """
    dyn, static = eqx.partition(problem, eqx.is_array)
    return jax.lax.map(lambda d: _core(solver, eqx.combine(d, static), max_steps), dyn)


def _traced_core_map(solver, problem, max_steps):  # type: ignore[no-untyped-def]
    _TRACES["fit"] += 1
    return batch_core(solver, problem, max_steps)


_core_batch_jit = {
    "vmap": eqx.filter_jit(eqx.filter_vmap(_traced_core, in_axes=(None, eqx.if_array(0), None))),
    "map": eqx.filter_jit(_traced_core_map),
}
_make_fit_jit = eqx.filter_jit(_make_fit)


def batch_problem(
    model: LimbModel, coords: Any, z: Any, init: LimbParams, *, fixed: Sequence[str] = (),
    weights: Any = None, analytic: bool = True,
) -> LimbProblem:
    """Validate a batch and pad its pixel axis to the bucket size: the :class:`LimbProblem` of :func:`fit_batch`.

    Parameters
    ----------
    model, coords, z, init, fixed, weights, analytic
        As :func:`fit_batch`.

    Returns
    -------
    LimbProblem
        The batched problem, arrays ``(B, ...)`` on the device.

    Raises
    ------
    LimbInputError
        As :func:`fit`.
    """
    coords_, z_, w_, theta, free_idx = validate_inputs(model, coords, z, init, fixed, weights, batched=True)
    size = bucket_size(z_.shape[1])
    if size != z_.shape[1]:
        packed = [pad_pixels(c, zi, wi, size) for c, zi, wi in zip(coords_, z_, w_)]
        coords_, z_, w_ = (np.stack([p[i] for p in packed]) for i in range(3))
    return LimbProblem(model, free_idx, analytic, jnp.asarray(theta), jnp.asarray(coords_), jnp.asarray(z_), jnp.asarray(w_))


# ============================================================================ held by a mask
def _held_mask(model: LimbModel, free_idx: tuple[int, ...], held: Sequence[str]) -> np.ndarray:
    """The 0/1 mask over ``free_idx`` of :func:`fit`'s ``held`` (validated)."""
    free = [model.param_names[i] for i in free_idx]
    unknown = sorted(set(held) - set(free))
    if unknown:
        raise LimbInputError(f"`held` names parameters that are not free {unknown}; the free ones are {free}")
    mask = np.array([0.0 if n in held else 1.0 for n in free])
    if not mask.any():
        raise LimbInputError("`held` holds every free parameter: nothing to estimate")
    return mask


def _without_held(res: LimbFit, held: Sequence[str]) -> LimbFit:
    """A masked fit's :class:`LimbFit` over its estimated parameters only (as the fit with them fixed)."""
    keep = [i for i, n in enumerate(res.free) if n not in held]
    cov = np.asarray(res.covariance)[np.ix_(keep, keep)]  # on the host: no gather program
    return LimbFit(params=res.params, free=tuple(res.free[i] for i in keep), covariance=jax.device_put(cov),
                   sigma2=res.sigma2, rms=res.rms, n_pixels=res.n_pixels, n_steps=res.n_steps, result=res.result,
                   solver=res.solver)


# ============================================================================ API
def fit(model: LimbModel, coords: Any, z: Any, init: LimbParams, solver: AbstractLimbSolver | None = None, *,
        fixed: Sequence[str] = (), weights: Any = None, analytic: bool = True, max_steps: int = 256,
        throw: bool = True, held: Sequence[str] | None = None) -> LimbFit:
    """Fit a limb model to pixel intensities.

    Parameters
    ----------
    model : any limb model of :mod:`jaxlimb.models` (the sigmoids ``CIRCLE``, ``ELLIPSE``, ``LINEAR``, ...).
    coords : pixel coordinates ``(n, 2)`` as ``(row, col)`` (``(n,)`` for the linear model).
    z : observed intensities ``(n,)``.
    init : initial guess (a parameter container of the model); fixed parameters are held at its values.
    solver : a solver object (default :class:`~jaxlimb.fitting.solvers.NormalLM`; :data:`~jaxlimb.fitting.SOLVERS`).
    fixed : names of parameters to hold fixed, e.g. ``("k", "ymax", "ymin")``.
    weights : optional per-pixel weights ``(n,)`` (``1/sigma_i``; 0 drops a pixel).
    analytic : use the paper's analytic Jacobian (default) or autodiff.
    max_steps : iteration limit.
    throw : raise :class:`~jaxlimb.errors.ConvergenceError` if the fit did not converge;
        with ``throw=False`` inspect ``result`` / ``converged`` instead.
    held : parameters (not in ``fixed``) held at their ``init`` values by a run-time mask
        (:class:`~jaxlimb.fitting.solvers.LimbProblem`'s ``mask``): every call with the same ``fixed`` -- whatever
        it holds and whatever ``max_steps`` -- runs one compiled program (e.g. a fit with the PSF free, then with it
        held).  The answer is that of ``fixed=(*fixed, *held)``.  ``None`` (default): no mask.  Solvers without
        :attr:`~jaxlimb.fitting.solvers.AbstractLimbSolver.masks` get ``held`` added to ``fixed``.

    Returns
    -------
    LimbFit

    Raises
    ------
    LimbInputError
        Non-finite values, empty or too few pixels, wrong shapes, ``radius``/``a``/``k`` <= 0.
    ConvergenceError
        The solver did not converge (``throw=True``).

    Examples
    --------
    A circular sigmoid (Eq. 16 of Mortari et al.) with 2 DN of noise on a 64 x 64 image, all six parameters free:

    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> import numpy as np
    >>> from jaxlimb.fitting import fit
    >>> from jaxlimb.models import CIRCLE, CircleParams
    >>> rc = np.argwhere(np.ones((64, 64))).astype(float)  # (row, col) of every pixel
    >>> d = np.hypot(rc[:, 0] - 31.3, rc[:, 1] - 30.6)
    >>> z = 10.0 + 190.0 / (1.0 + np.exp(2.0 * (d - 20.0))) + np.random.default_rng(0).normal(0.0, 2.0, len(d))
    >>> res = fit(CIRCLE, rc, z, CircleParams(r0=32.0, c0=32.0, radius=18.0, k=1.0, ymax=180.0, ymin=20.0))
    >>> print(bool(res.converged), np.round([res.params.r0, res.params.c0, res.params.radius], 3))
    True [31.301 30.594 20.001]
    >>> print(round(float(res.std["r0"]), 4))  # 1-sigma of the centre's row (px)
    0.0023
    """
    solver = NormalLM() if solver is None else solver
    problem, held = _single_problem(model, coords, z, init, solver, fixed, weights, analytic, held)
    res = _solve(solver, problem, max_steps, held)
    if throw and not bool(res.converged):
        raise ConvergenceError(f"{solver.name} did not converge after {int(res.n_steps)} steps: {res.message}")
    return res


def _single_problem(model: LimbModel, coords: Any, z: Any, init: LimbParams, solver: AbstractLimbSolver,
                    fixed: Sequence[str], weights: Any, analytic: bool,
                    held: Sequence[str] | None) -> tuple[LimbProblem, Sequence[str] | None]:
    """The validated :class:`LimbProblem` of :func:`fit` (pixels padded to their bucket, on the device) and the
    parameters its mask holds (``held`` joins ``fixed`` for a solver that cannot mask)."""
    _check_precision()
    if held is not None and not (solver.masks and solver.jittable):
        fixed, held = (*fixed, *held), None
    coords_, z_, w_, theta, free_idx = validate_inputs(model, coords, z, init, fixed, weights, batched=False)
    mask = None if held is None else _to_device(_held_mask(model, free_idx, held))
    coords_, z_, w_ = pad_pixels(coords_, z_, w_, bucket_size(z_.shape[0]))
    return LimbProblem(model, free_idx, analytic, *(_to_device(a) for a in (theta, coords_, z_, w_)), mask), held


def _solve(solver: AbstractLimbSolver, problem: LimbProblem, max_steps: int, held: Sequence[str] | None) -> LimbFit:
    """One fit of ``problem``: the compiled core (a masked fit reported over its estimated parameters), or the
    solver's own loop for a non-jittable solver."""
    if solver.jittable:
        res = _core_jit(solver, problem, max_steps)
        return _without_held(res, held) if held else res
    y0 = _to_device(np.asarray(problem.theta0)[list(problem.free_idx)])  # on the host: no gather program
    y, n_steps, result = solver.solve(problem, y0, max_steps)
    return _make_fit_jit(problem, y, n_steps, result, solver.name)


def fit_batch(
    model: LimbModel, coords: Any, z: Any, init: LimbParams, solver: AbstractLimbSolver | None = None, *,
    fixed: Sequence[str] = (), weights: Any = None, analytic: bool = True, max_steps: int = 256, strategy: str = "map",
) -> LimbFit:
    """Fit a batch of problems in one compiled call (Monte Carlo, many images).

    ``coords`` is ``(B, N, 2)``, ``z`` and ``weights`` ``(B, N)`` (build them with
    :func:`pack_pixels` for pixel sets of different sizes; zero weights mark
    padding), and ``init`` holds ``(B,)`` arrays in each field.  Never raises on
    non-convergence: check ``result.converged`` per member.  ``N`` is padded to
    its bucket so repeated calls with similar sizes do not recompile.

    ``strategy="map"`` (default) runs the members one after another inside one
    program (``jax.lax.map``): on a CPU each member's working set (~100 kB for
    10^4 pixels) stays in cache and each stops at its own iteration count.
    ``strategy="vmap"`` vectorises the members (``jax.vmap``; the while loop
    then runs every member to the slowest one's count): the choice for GPUs.
    Measured in ``benchmarks/solvers.py``.

    Parameters
    ----------
    model, solver, fixed, analytic, max_steps
        As :func:`fit`.
    coords : array_like (B, N, 2)
        Pixel coordinates ``(row, col)`` of each member (``(B, N)`` for the linear model).
    z : array_like (B, N)
        Observed intensities.
    init : LimbParams
        Initial guesses, a ``(B,)`` array in each field.
    weights : array_like (B, N), optional
        Per-pixel weights; 0 marks padding.
    strategy : {"map", "vmap"}
        How the members run (see above).

    Returns
    -------
    LimbFit
        The fits, fields with a leading batch axis ``(B, ...)``.

    Raises
    ------
    LimbInputError
        Invalid input (as :func:`fit`), an unknown ``strategy`` or a solver that is not jittable.
    """
    if strategy not in _core_batch_jit:
        raise LimbInputError(f"`strategy` must be one of {sorted(_core_batch_jit)}, got {strategy!r}")
    _check_precision()
    solver = NormalLM() if solver is None else solver
    if not solver.jittable:
        raise LimbInputError(f"`solver` {solver.name} cannot be batched (not jittable); loop over `fit` instead")
    problem = batch_problem(model, coords, z, init, fixed=fixed, weights=weights, analytic=analytic)
    return _core_batch_jit[strategy](solver, problem, max_steps)
