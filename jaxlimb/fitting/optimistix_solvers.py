"""The optimistix solvers behind :func:`jaxlimb.fitting.fit` (imported on first use).

:class:`Optimistix` runs any optimistix least-squares solver or minimiser on the limb problem
with what the default solver has (fused analytic Jacobian, normal equations, coarse-to-fine
start, the stopping rule on the parameter step: :class:`StepStop`);
:func:`optimistix_normal_lm` runs the default's Marquardt-scaled Cholesky descent inside
optimistix's Gauss--Newton machinery; :class:`ScaledBFGS` is optimistix's BFGS started at the
loss's scale.  Kept apart from :mod:`jaxlimb.fitting.solvers` so that the
default path does not import optimistix and lineax (~0.06 s of every command's start-up).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx
from jaxtyping import Array, Float, PyTree, Scalar

from .problem import AbstractLimbSolver, FitResult, coarse_problem, finish_result, fused_residual_fn

OPTX_RTOL = 1e-10
OPTX_ATOL = 1e-6
r"""Tolerances of the optimistix solvers that keep optimistix's own stopping test (``bfgs``).

optimistix's Cauchy test stops on an *accepted* step with
:math:`|\Delta y_j| < atol + rtol|y_j|` for every parameter **and**
:math:`|\Delta r_i| < atol + rtol|r_i|` for every pixel residual.  Residuals near zero make
``atol`` an absolute bound in DN on every pixel: with ``atol = 1e-10`` the last steps' changes
sit at the rounding level of the loss and are accepted or rejected at random.  ``atol = 1e-6``
(px and DN, far below any noise) stops where the estimate has converged.  The Gauss--Newton
family is stopped by :class:`StepStop` instead, with :class:`NormalLM`'s tolerances.
"""


class StepStop(optx.AbstractLeastSquaresSolver):  # type: ignore[misc]
    r"""An optimistix Gauss--Newton-family solver stopped by :class:`NormalLM`'s rule on the parameter step.

    ``solver``'s own ``init``/``step`` run unchanged (its descent, damping and trust region); only the
    stopping test differs.  Stop when the step :math:`\delta` proposed from the current point ``y``
    (``y_eval - y`` after the search's update: the next trial) satisfies
    :math:`\max|\delta| \le atol + rtol\max|y|` in the parameters' own units (px, DN, 1/px): as
    :class:`NormalLM`'s test on its damped step and MINPACK's ``xtol`` test on the trust region, a
    step shortened by the trust region counts.  Or when, right after an accepted step, the local
    model's predicted reduction of :math:`\delta`, :math:`-(r^\top J\delta + \tfrac12\|J\delta\|^2)`,
    is below the rounding bound of the loss, :math:`\gamma_n = n\,\epsilon` times
    :math:`\tfrac12\|r\|^2` for :math:`n` residuals (Higham 2002, Sec. 4.2): the trust-region
    ratio cannot tell such a step from rounding (MINPACK stops there too, ``info = 6``), and the
    answer is then ``y + delta``, the minimiser of a local model that is exact to rounding.

    optimistix's Cauchy test (``solver.terminate``) instead needs one more *accepted* step with
    every pixel's residual change below ``atol`` DN.  At the minimum of a non-zero-residual problem
    (~10^4 pixels of noise) that step's reduction is below the loss's rounding, the ratio test
    accepts or rejects it at random and each rejection shrinks the region by 4: up to ~20 steps
    after the estimate has converged, the tail of the step counts that a vmapped batch waits for
    (``benchmarks/optimistix_plumbing.py``).
    """

    solver: optx.AbstractGaussNewton
    rtol: float
    atol: float
    norm: Callable[[PyTree], Scalar] = optx.max_norm

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):  # type: ignore[no-untyped-def]
        """``solver``'s state, with the stop and last-step flags.

        Parameters
        ----------
        fn, y, args, options, f_struct, aux_struct, tags : as ``optimistix.AbstractLeastSquaresSolver.init``.

        Returns
        -------
        tuple : ``(solver state, stop, take the last proposed step)``.
        """
        return self.solver.init(fn, y, args, options, f_struct, aux_struct, tags), jnp.array(False), jnp.array(False)

    def step(self, fn, y, args, options, state, tags):  # type: ignore[no-untyped-def]
        """``solver``'s step, then the stopping tests on the step it proposes next (class docstring).

        Parameters
        ----------
        fn, y, args, options, state, tags : as ``optimistix.AbstractLeastSquaresSolver.step``.

        Returns
        -------
        tuple : ``(y, state, aux)`` as ``solver.step``, the state with this class's flags.
        """
        y, inner, aux = self.solver.step(fn, y, args, options, state[0], tags)
        step = inner.y_eval - y
        small = self.norm(step) <= self.atol + self.rtol * self.norm(y)
        r = inner.f_info.residual  # at the accepted point y
        jd = inner.f_info.jac.mv(step)
        predicted = -(jnp.vdot(r, jd) + 0.5 * jnp.vdot(jd, jd))  # of the local model, without cancellation
        floor = r.size * jnp.finfo(r.dtype).eps * 0.5 * jnp.vdot(r, r)  # rounding bound of the loss (gamma_n)
        undecidable = ~inner.first_step & (inner.num_steps_since_acceptance == 0) & (predicted <= floor)
        return y, (inner, (~inner.first_step & small) | undecidable, undecidable), aux

    def terminate(self, fn, y, args, options, state, tags):  # type: ignore[no-untyped-def]
        """Whether to stop (this class's rule) and ``solver``'s result.

        Parameters
        ----------
        fn, y, args, options, state, tags : as ``optimistix.AbstractLeastSquaresSolver.terminate``.

        Returns
        -------
        tuple : ``(stop, result)``.
        """
        del fn, y, args, options, tags
        return state[1], state[0].result

    def postprocess(self, fn, y, aux, args, options, state, tags, result):  # type: ignore[no-untyped-def]
        """``solver``'s postprocess of ``y``, or of ``y + delta`` when the last step was undecidable.

        Parameters
        ----------
        fn, y, aux, args, options, state, tags, result : as ``optimistix.AbstractLeastSquaresSolver.postprocess``.

        Returns
        -------
        tuple : ``(y, aux, stats)``.
        """
        y = jax.tree.map(lambda a, b: jnp.where(state[2], a, b), state[0].y_eval, y)  # the undecidable last step
        return self.solver.postprocess(fn, y, aux, args, options, state[0], tags, result)


class ScaledBFGS(optx.AbstractBFGS):  # type: ignore[misc]
    r"""optimistix's BFGS started from the inverse Hessian :math:`H_0 = I/\|\nabla f(y_0)\|_\infty`.

    Everything else is ``optimistix.BFGS`` (the inverse-Hessian update, the Newton descent, the
    backtracking Armijo search, the Cauchy stopping test at ``rtol``/``atol``).  With ``H_0 = I`` the
    first trial step is the raw gradient of the loss, ~10^6 (DN^2 per px) at a limb start a pixel off:
    the Armijo search halves it ~20 times to a fraction of a pixel, and as the update keeps the identity's
    scale in the directions it has not yet sampled, again at each new direction (~230 steps a fit, 80 %
    of them rejected trials).  Scaling the start so that its first step moves the parameter of largest
    gradient by one unit (Liu & Nocedal 1989's first step, :math:`1/\|g_0\|`) gives the update the
    loss's scale from the start: the same minimum in ~60 steps.
    """

    rtol: float
    atol: float
    norm: Callable[[PyTree], Scalar] = optx.max_norm
    use_inverse: bool = True
    descent: optx.NewtonDescent = optx.NewtonDescent(linear_solver=lx.Cholesky())
    search: optx.BacktrackingArmijo = optx.BacktrackingArmijo()
    verbose: Callable[..., None] = eqx.field(static=True, default=lambda **kw: None)

    def init_hessian(self, y, f, grad):  # type: ignore[no-untyped-def]
        """optimistix's identity placeholder, and a flag: the start's scale is still to be set.

        Parameters
        ----------
        y, f, grad : as ``optimistix.AbstractQuasiNewton.init_hessian``.

        Returns
        -------
        tuple : ``(f_info, True)``.
        """
        f_info, _ = super().init_hessian(y, f, grad)
        return f_info, jnp.array(True)

    def update_hessian(self, y, y_eval, f_info, f_eval_info, hessian_update_state):  # type: ignore[no-untyped-def]
        r"""BFGS's update (``optimistix.AbstractBFGS.update_hessian``), the first from :math:`I/\|g_0\|_\infty`.

        Parameters
        ----------
        y, y_eval, f_info, f_eval_info : as ``optimistix.AbstractQuasiNewton.update_hessian``.
        hessian_update_state : jax.Array () of bool
            Whether this is the start (its gradient sets the scale).

        Returns
        -------
        tuple : ``(f_info with the updated inverse Hessian, False)``.
        """
        g = f_eval_info.grad
        h = f_info.hessian_inv
        scale = 1.0 / jnp.maximum(self.norm(g), jnp.finfo(g.dtype).tiny)
        start = jnp.where(hessian_update_state, scale * jnp.eye(g.size, dtype=g.dtype), h.pytree)
        h = lx.PyTreeLinearOperator(start, h.out_structure(), lx.positive_semidefinite_tag)
        f_info = type(f_info)(f_info.f, f_info.grad, h)
        out, _ = super().update_hessian(y, y_eval, f_info, f_eval_info, None)
        return out, jnp.array(False)


class Optimistix(AbstractLimbSolver):
    """Any optimistix least-squares solver or minimiser, given what the default solver has.

    With ``fused=True`` (default) and the analytic Jacobian, the residual handed to optimistix
    is :func:`~jaxlimb.fitting.problem.fused_residual_fn`: a ``jax.custom_jvp`` whose primal
    pass computes the intensities and the Jacobian columns together, so optimistix's
    ``jax.linearize`` gets the paper's Jacobian as one ``(n, q)`` matrix instead of tracing the
    model.  With ``normal=True`` (default) the linear solver of the solver's descent
    (``LevenbergMarquardt``, ``Dogleg``, ``GaussNewton``: their ``descent.linear_solver``) is
    replaced by ``lineax.Normal(lineax.Cholesky())``: the ``q x q`` normal equations by
    Cholesky instead of a QR of the ``n x q`` (or stacked ``(n + q) x q``) operator.  Both
    change the cost of a step, not the algorithm.  With ``step_stop=True`` (default) a
    Gauss--Newton-family solver (``LevenbergMarquardt``, ``Dogleg``, ``GaussNewton``) is stopped
    by :class:`NormalLM`'s rule on the parameter step instead of optimistix's Cauchy test
    (:class:`StepStop`), its steps, damping and trust-region search unchanged: the Cauchy test
    spends the tail of the step counts after convergence.  ``Optimistix(solver, fused=False,
    normal=False, coarse_stride=1, step_stop=False)`` is optimistix as it comes.  With
    ``coarse_stride > 1`` (default 4, as :class:`NormalLM`) the solver first runs on every
    ``coarse_stride``-th pixel to ``coarse_tol_px``, then on all pixels from there
    (:meth:`_coarse_phase`); ``n_steps`` counts both phases.  With ``step_stop=False`` choose
    ``atol`` with :data:`OPTX_ATOL` in mind: it bounds every pixel's residual change in DN.

    Examples
    --------
    >>> import optimistix as optx
    >>> Optimistix(optx.Dogleg(rtol=1e-10, atol=1e-10))  # doctest: +SKIP
    """

    solver: optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser
    fused: bool = eqx.field(static=True, default=True)
    normal: bool = eqx.field(static=True, default=True)
    coarse_stride: int = eqx.field(static=True, default=4)
    coarse_tol_px: float = eqx.field(static=True, default=1e-2)
    coarse_min_pixels: int = eqx.field(static=True, default=1024)
    step_stop: bool = eqx.field(static=True, default=True)

    @property
    def name(self) -> str:
        return type(self.solver).__name__

    def configured(self) -> optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser:
        """The optimistix solver as run: with the normal-equations linear solve if ``normal``.

        Returns
        -------
        optimistix.AbstractLeastSquaresSolver or optimistix.AbstractMinimiser
            ``solver``, its descent's linear solver replaced by ``lineax.Normal(lineax.Cholesky())`` when ``normal``
            and the descent has one.
        """
        descent = getattr(self.solver, "descent", None)
        if not self.normal or not isinstance(getattr(descent, "linear_solver", None), lx.AbstractLinearSolver):
            return self.solver
        return eqx.tree_at(lambda s: s.descent.linear_solver, self.solver, lx.Normal(lx.Cholesky()))

    def solve(self, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        """Run ``optimistix.least_squares`` (after the coarse phase) with ``throw=False``.

        Parameters
        ----------
        problem : LimbProblem
            The problem.
        y0 : jax.Array (q,)
            Start of the free parameters.
        max_steps : int
            Iteration limit of each phase.

        Returns
        -------
        y : jax.Array (q,)
            The estimate.
        n_steps : jax.Array () of int
            Steps of both phases.
        result : FitResult
            optimistix's outcome by name (:func:`fit_result`), ``diverged`` at an inadmissible point.
        """
        residual = (fused_residual_fn(problem.model, problem.free_idx) if self.fused and problem.analytic
                    else problem.residual)
        solver = self.configured()
        if self.step_stop and isinstance(solver, optx.AbstractGaussNewton):
            solver = StepStop(solver, solver.rtol, solver.atol)
        y0, steps = self._coarse_phase(residual, solver, problem, y0, max_steps)
        sol = optx.least_squares(residual, solver, y0, args=problem.args, max_steps=max_steps, throw=False)
        return sol.value, steps + sol.stats["num_steps"], finish_result(problem, sol.value, fit_result(sol.result))

    def _coarse_phase(self, residual, solver, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        """:class:`NormalLM`'s coarse-to-fine start: the same solver on every ``coarse_stride``-th pixel.

        Runs to ``coarse_tol_px`` (the basin of the full problem's minimum) and hands its answer
        to the full-data solve, which alone decides convergence: the answer is the full-data
        minimum either way, only the early, far-from-converged steps get cheaper.  Skipped on
        fewer than ``coarse_min_pixels`` pixels and for solvers without ``rtol``/``atol``; a
        failed coarse phase starts the full one afresh.
        """
        n_pix = problem.z.shape[-1]
        if self.coarse_stride <= 1 or n_pix < self.coarse_min_pixels or not hasattr(solver, "atol"):
            return y0, jnp.asarray(0)
        loose = eqx.tree_at(lambda s: (s.rtol, s.atol), solver, (1e-6, self.coarse_tol_px))
        coarse = coarse_problem(problem, self.coarse_stride)
        sol = optx.least_squares(residual, loose, y0, args=coarse.args, max_steps=max_steps, throw=False)
        ok = (sol.result == optx.RESULTS.successful) & coarse.admissible(sol.value)
        return jnp.where(ok, sol.value, y0), sol.stats["num_steps"]


def fit_result(result: Any) -> FitResult:
    """An optimistix (or lineax) result as a :class:`FitResult` of the same name (jittable).

    A name :class:`FitResult` does not have becomes ``solver_failed``: never ``successful``.

    Parameters
    ----------
    result : optimistix.RESULTS
        The outcome of an optimistix solve (scalar or batched).

    Returns
    -------
    FitResult
        The outcome of the same name.
    """
    out = FitResult.solver_failed
    for name in optx.RESULTS._name_to_item:  # every result optimistix can return
        if hasattr(FitResult, name):
            out = FitResult.where(result == getattr(optx.RESULTS, name), getattr(FitResult, name), out)
    return out


class _NormalState(eqx.Module):
    jtj: Float[Array, "q q"]
    jtr: Float[Array, " q"]


class MarquardtCholeskyDescent(optx.AbstractDescent):  # type: ignore[misc]
    r"""Damped Gauss--Newton step from the normal equations, Marquardt-scaled.

    Solves :math:`(J^\top J + \lambda\,\mathrm{diag}(J^\top J))\,\delta = -J^\top r`
    by Cholesky, with :math:`\lambda = \lambda_0 / s` for the trust-region step
    size ``s``.  ``J`` is materialised once per accepted point (``p`` JVPs).
    """

    lambda0: float = 1e-3

    def init(self, y, f_info_struct):  # type: ignore[no-untyped-def]
        """Zero normal equations (optimistix's ``AbstractDescent.init``).

        Parameters
        ----------
        y : jax.Array (q,)
            The start (sets the size and dtype).
        f_info_struct : optimistix.FunctionInfo
            Structure of the function information (not used).

        Returns
        -------
        _NormalState
            ``J^T J = 0`` ``(q, q)``, ``J^T r = 0`` ``(q,)``.
        """
        q = y.shape[0]
        return _NormalState(jnp.zeros((q, q), y.dtype), jnp.zeros((q,), y.dtype))

    def query(self, y, f_info, state):  # type: ignore[no-untyped-def]
        r"""Form the normal equations at an accepted point (``AbstractDescent.query``).

        Parameters
        ----------
        y : jax.Array (q,)
            The accepted point (not used).
        f_info : optimistix.FunctionInfo.ResidualJac
            Residual and Jacobian operator there.
        state : _NormalState
            The previous state (not used).

        Returns
        -------
        _NormalState
            :math:`J^\top J` and :math:`J^\top r`, the Jacobian materialised once.
        """
        del y, state
        jac = f_info.jac.as_matrix()
        return _NormalState(jac.T @ jac, jac.T @ f_info.residual)

    def step(self, step_size, state):  # type: ignore[no-untyped-def]
        r"""The damped step for a trust-region size (``AbstractDescent.step``).

        Parameters
        ----------
        step_size : jax.Array ()
            The search's step size ``s``; the damping is :math:`\lambda = \lambda_0 / s`.
        state : _NormalState
            The normal equations of :meth:`query`.

        Returns
        -------
        delta : jax.Array (q,)
            The step (0 if the solve is not finite).
        result : optimistix.RESULTS
            ``successful``, or ``singular`` when the Cholesky solve is not finite.
        """
        tiny = jnp.finfo(state.jtr.dtype).tiny
        lam = self.lambda0 / jnp.maximum(step_size, tiny)
        d = jnp.diagonal(state.jtj)
        scale = jnp.maximum(d, 1e-12 * jnp.max(d) + tiny)
        a = state.jtj + jnp.diag(lam * scale)
        chol = jnp.linalg.cholesky(a)
        delta = -jax.scipy.linalg.cho_solve((chol, True), state.jtr)
        ok = jnp.all(jnp.isfinite(delta))
        delta = jnp.where(ok, delta, 0.0)
        return delta, optx.RESULTS.where(ok, optx.RESULTS.successful, optx.RESULTS.singular)


class _NormalLMCore(optx.AbstractGaussNewton):  # type: ignore[misc]
    rtol: float
    atol: float
    norm: Callable[[PyTree], Scalar]
    descent: MarquardtCholeskyDescent
    search: optx.ClassicalTrustRegion
    verbose: Callable[..., None]


def optimistix_normal_lm(rtol: float = 1e-10, atol: float = 1e-10, lambda0: float = 1e-3) -> Optimistix:
    """:class:`MarquardtCholeskyDescent` run by optimistix's ``AbstractGaussNewton`` + ``ClassicalTrustRegion``.

    Parameters
    ----------
    rtol, atol : float
        optimistix's relative and absolute tolerances (its Cauchy test on steps and residuals).
    lambda0 : float
        Damping at unit trust-region step size.

    Returns
    -------
    Optimistix
        The solver, ready for :func:`~jaxlimb.fitting.fit`.
    """
    core = _NormalLMCore(
        rtol=rtol,
        atol=atol,
        norm=optx.max_norm,
        descent=MarquardtCholeskyDescent(lambda0),
        search=optx.ClassicalTrustRegion(),
        verbose=_quiet,
    )
    return Optimistix(core)


def _quiet(**kwargs: Any) -> None:
    del kwargs
