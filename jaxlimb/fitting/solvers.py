r"""Solvers for the limb least-squares problem, all behind one interface.

Every solver is an :class:`AbstractLimbSolver` (an ``equinox.Module``) with a
``solve(problem, y0, max_steps)`` method returning the free-parameter estimate,
the number of iterations and a :class:`FitResult`.  Choose by object:

=============================  =====================================================
solver                         what it is
=============================  =====================================================
:class:`NormalLM` (default)    Levenberg--Marquardt on the normal equations, run by
                               optimistix (``AbstractGaussNewton`` + trust region)
                               with our Marquardt-scaled Cholesky descent
:class:`Optimistix`            any optimistix least-squares solver or minimiser as
                               it comes (``GaussNewton``, ``LevenbergMarquardt``,
                               ``Dogleg``, ``BFGS``, ...)
:class:`PaperGaussNewton`      the paper's own iteration, Eq. (15) of Mortari et al.
:class:`ScipyLeastSquares`     ``scipy.optimize.least_squares`` baseline (not jittable)
=============================  =====================================================

Why :class:`NormalLM` is the default.  optimistix's ``LevenbergMarquardt``
solves the damped step as a linear least-squares problem by QR of the stacked
``[J; sqrt(lambda) I]`` operator, which it rebuilds from a ``jax.linearize``
closure at every step, and damps with ``lambda I`` (scale-blind: ``k ~ 3`` and
``ymax ~ 200`` share one damping).  For limb fits ``J`` is tall and thin
(``n ~ 10^4`` pixels, ``p <= 8``), so forming ``J^T J`` once per accepted step
(``O(n p^2)``) and solving the ``p x p`` system by Cholesky is much cheaper,
and Marquardt's ``diag(J^T J)`` scaling makes the damping unit-free.  The
normal equations square the condition number, which is harmless here
(``cond(J) < 10^4`` for these parameters in float64) -- the tests compare
against SciPy's QR-based MINPACK to 1e-6 px.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int, PyTree, Scalar

from ..models import LimbModel
from ._problem import expand, fused_residual_fn, jacobian_fn, residual_fn


class FitResult(optx.RESULTS):  # type: ignore[misc]
    """Outcome of a fit: optimistix's results plus the limb-specific failures."""

    diverged = (
        "The fit diverged (non-finite parameters, or radius / semi-axis / k left the "
        "admissible range > 0). Start closer to the limb (e.g. from a Taubin circle) "
        "or use a damped solver (NormalLM, LevenbergMarquardt, Dogleg)."
    )


# ============================================================================ problem
class LimbProblem(eqx.Module):
    """A limb least-squares problem (one image, or one member of a vmapped batch).

    Attributes
    ----------
    model : the sigmoid model (static).
    free_idx : indices of the free parameters in the model's parameter vector (static).
    analytic : use the paper's analytic Jacobian (True) or autodiff (False) (static).
    theta0 : full parameter vector; its fixed entries are held, its free ones are the start.
    coords : pixel coordinates, ``(n, 2)`` ``(row, col)`` (or ``(n,)`` for the linear model).
    z : observed intensities ``(n,)``.
    w : per-pixel weights ``(n,)``: 1 for data, 0 for padding (or 1/sigma_i).
    """

    model: LimbModel = eqx.field(static=True)
    free_idx: tuple[int, ...] = eqx.field(static=True)
    analytic: bool = eqx.field(static=True)
    theta0: Float[Array, " p"]
    coords: Array
    z: Float[Array, " n"]
    w: Float[Array, " n"]

    @property
    def args(self) -> tuple[Array, Array, Array, Array]:
        return (self.theta0, self.coords, self.z, self.w)

    @property
    def residual(self) -> Callable[[Array, Any], Array]:
        return residual_fn(self.model, self.free_idx, self.analytic)

    def jacobian(self, y: Array) -> Float[Array, "n q"]:
        """Weighted Jacobian of the residuals w.r.t. the free parameters."""
        jf = jacobian_fn(self.model, self.analytic)
        full = jf(expand(self.theta0, self.free_idx, y), self.coords)
        return self.w[:, None] * full[:, jnp.asarray(self.free_idx)]

    def normal_equations(self, y: Array) -> tuple[Array, Array, Array]:
        """``(J^T J, J^T r, r^T r)`` over the free parameters in one fused pass.

        The Jacobian is built transposed, ``(q, n)``, which on CPU is ~2x
        faster than the ``(n, q)`` layout for these reductions.
        """
        theta = expand(self.theta0, self.free_idx, y)
        params = self.model.params_type.from_vector(theta)
        if self.analytic:
            f, cols = self.model.intensity_and_jacobian_columns(params, self.coords)
            r = self.w * (f - self.z)
            jt = jnp.stack([cols[i] for i in self.free_idx], axis=0) * self.w
        else:
            r = self.w * (self.model.intensity(params, self.coords) - self.z)
            jt = self.jacobian(y).T
        return jt @ jt.T, jt @ r, r @ r

    def admissible(self, y: Array) -> Bool[Array, ""]:
        """Finite, and every scale parameter (radius, a, k, rho) strictly positive."""
        theta = expand(self.theta0, self.free_idx, y)
        ok = jnp.all(jnp.isfinite(theta))
        for i, name in enumerate(self.model.param_names):
            if name in _POSITIVE:
                ok = ok & (theta[i] > 0)
        return ok


_POSITIVE = frozenset({"radius", "a", "k", "rho"})


# ============================================================================ base
class AbstractLimbSolver(eqx.Module):
    """Base class of the solvers behind :func:`jaxlimb.fitting.fit`."""

    jittable: ClassVar[bool] = True

    @abc.abstractmethod
    def solve(
        self, problem: LimbProblem, y0: Float[Array, " q"], max_steps: int
    ) -> tuple[Float[Array, " q"], Int[Array, ""], FitResult]:
        """Return ``(y, n_steps, result)`` for the free parameters."""

    @property
    def name(self) -> str:
        return type(self).__name__


def _finish(problem: LimbProblem, y: Array, result: Any) -> FitResult:
    result = FitResult.promote(result) if not isinstance(result, FitResult) else result
    return FitResult.where(
        (result == FitResult.successful) & ~problem.admissible(y), FitResult.diverged, result
    )


# ============================================================================ optimistix
OPTX_RTOL = 1e-10
OPTX_ATOL = 1e-6
r"""Tolerances of the optimistix solvers registered by name (``--solver optx-lm`` ...).

optimistix's Cauchy test stops on an *accepted* step with
:math:`|\Delta y_j| < atol + rtol|y_j|` for every parameter **and**
:math:`|\Delta r_i| < atol + rtol|r_i|` for every pixel residual.  Residuals near zero make
``atol`` an absolute bound in DN on every pixel: with ``atol = 1e-10`` the last steps' changes
sit at the rounding level, the loss goes up or down by 1e-9 of itself at random, steps are
rejected and the trust region shrinks for ~20 extra steps (``benchmarks/optimistix_plumbing.py``
shows the row).  ``atol = 1e-6`` (px and DN, far below any noise) stops where the estimate
has converged: the answers agree with :class:`NormalLM` (``rtol = atol = 1e-10`` on the
step) to ~1e-9 px.
"""


class Optimistix(AbstractLimbSolver):
    """Any optimistix least-squares solver or minimiser, given what the default solver has.

    With ``fused=True`` (default) and the analytic Jacobian, the residual handed to optimistix
    is :func:`~jaxlimb.fitting._problem.fused_residual_fn`: a ``jax.custom_jvp`` whose primal
    pass computes the intensities and the Jacobian columns together, so optimistix's
    ``jax.linearize`` gets the paper's Jacobian as one ``(n, q)`` matrix instead of tracing the
    model.  With ``normal=True`` (default) the linear solver of the solver's descent
    (``LevenbergMarquardt``, ``Dogleg``, ``GaussNewton``: their ``descent.linear_solver``) is
    replaced by ``lineax.Normal(lineax.Cholesky())``: the ``q x q`` normal equations by
    Cholesky instead of a QR of the ``n x q`` (or stacked ``(n + q) x q``) operator.  Both
    change the cost of a step, not the algorithm (its steps, damping and stopping rule).  So
    ``benchmarks/solvers.py`` compares algorithms, not plumbing (the remaining gap to
    :class:`NormalLM` is mostly the number of steps: optimistix's trust region starts at radius
    1 and its stopping rule, and :class:`NormalLM`'s coarse-to-fine phase).
    ``Optimistix(solver, fused=False, normal=False, coarse_stride=1)`` is optimistix as it
    comes.  With ``coarse_stride > 1`` (default 4, as :class:`NormalLM`) the solver first runs
    on every ``coarse_stride``-th pixel to ``coarse_tol_px``, then on all pixels from there
    (:meth:`_coarse_phase`); ``n_steps`` counts both phases.  Choose ``atol`` with
    :data:`OPTX_ATOL` in mind: it bounds every pixel's residual change in DN.

    Examples
    --------
    >>> import optimistix as optx
    >>> Optimistix(optx.Dogleg(rtol=OPTX_RTOL, atol=OPTX_ATOL))  # doctest: +SKIP
    """

    solver: optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser
    fused: bool = eqx.field(static=True, default=True)
    normal: bool = eqx.field(static=True, default=True)
    coarse_stride: int = eqx.field(static=True, default=4)
    coarse_tol_px: float = eqx.field(static=True, default=1e-2)
    coarse_min_pixels: int = eqx.field(static=True, default=1024)

    @property
    def name(self) -> str:
        return type(self.solver).__name__

    def configured(self) -> optx.AbstractLeastSquaresSolver | optx.AbstractMinimiser:
        """The optimistix solver as run: with the normal-equations linear solve if ``normal``."""
        descent = getattr(self.solver, "descent", None)
        if not self.normal or not isinstance(getattr(descent, "linear_solver", None), lx.AbstractLinearSolver):
            return self.solver
        return eqx.tree_at(lambda s: s.descent.linear_solver, self.solver, lx.Normal(lx.Cholesky()))

    def solve(self, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        residual = (fused_residual_fn(problem.model, problem.free_idx) if self.fused and problem.analytic
                    else problem.residual)
        solver = self.configured()
        y0, steps = self._coarse_phase(residual, solver, problem, y0, max_steps)
        sol = optx.least_squares(residual, solver, y0, args=problem.args, max_steps=max_steps, throw=False)
        return sol.value, steps + sol.stats["num_steps"], _finish(problem, sol.value, sol.result)

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
        coarse = _coarse(problem, self.coarse_stride)
        sol = optx.least_squares(residual, loose, y0, args=coarse.args, max_steps=max_steps, throw=False)
        ok = (sol.result == optx.RESULTS.successful) & coarse.admissible(sol.value)
        return jnp.where(ok, sol.value, y0), sol.stats["num_steps"]


def _coarse(problem: LimbProblem, k: int) -> LimbProblem:
    """Every ``k``-th pixel of ``problem`` (the coarse phase of coarse-to-fine)."""
    return LimbProblem(problem.model, problem.free_idx, problem.analytic, problem.theta0,
                       problem.coords[::k], problem.z[::k], problem.w[::k])


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
        q = y.shape[0]
        return _NormalState(jnp.zeros((q, q), y.dtype), jnp.zeros((q,), y.dtype))

    def query(self, y, f_info, state):  # type: ignore[no-untyped-def]
        del y, state
        jac = f_info.jac.as_matrix()
        return _NormalState(jac.T @ jac, jac.T @ f_info.residual)

    def step(self, step_size, state):  # type: ignore[no-untyped-def]
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


class NormalLM(AbstractLimbSolver):
    r"""Levenberg--Marquardt on the normal equations, fused (the default solver).

    One pass over the pixels per iteration computes :math:`J^\top J`,
    :math:`J^\top r` and :math:`r^\top r` at the trial point (the Jacobian built
    transposed, ``(q, n)``); the step solves
    :math:`(J^\top J + \lambda\,\mathrm{diag}(J^\top J))\,h = -J^\top r` by
    Cholesky; the gain ratio accepts or rejects it and updates
    :math:`\lambda` as in Nielsen (1999) (Madsen, Nielsen & Tingleff, *Methods
    for non-linear least squares problems*, Alg. 3.16).  Inadmissible trial
    points (``radius``, ``a``, ``k`` or ``rho`` <= 0, non-finite) are rejected
    like uphill steps.

    Converged when :math:`\max|h| \le atol + rtol \max|y|` (the criterion of
    Eq. 15's iteration); ``max_steps_reached`` otherwise; ``diverged`` if
    :math:`\lambda` exceeds ``1e16`` without an acceptable step.

    This is the engine of the fast path.  optimistix's own ``LevenbergMarquardt``
    (QR of the stacked ``[J; sqrt(lambda) I]`` operator rebuilt through
    ``jax.linearize`` at every step, ``lambda I`` damping) and the same descent
    run inside optimistix's ``AbstractGaussNewton`` (:func:`optimistix_normal_lm`)
    are kept as solvers and compared in ``benchmarks/solvers.py``.
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    lambda0: float = 1e-3
    coarse_stride: int = 4
    coarse_tol_px: float = 1e-2
    coarse_min_pixels: int = 1024

    def solve(self, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        y, n, result, _ = self.solve_normal(problem, y0, max_steps)
        return y, n, result

    def solve_normal(self, problem: LimbProblem, y0: Array, max_steps: int):  # noqa: ANN201
        """As :meth:`solve`, plus ``(J^T J, J^T r, r^T r)`` at the solution (reused for the covariance).

        Coarse-to-fine: on ``coarse_min_pixels`` or more pixels, the iteration first
        runs on every ``coarse_stride``-th pixel until its steps are below
        ``coarse_tol_px`` (the basin of the full problem's minimum), then on all
        pixels to the full tolerance.  The answer is the full-data least-squares
        minimum either way (the final convergence test is on all pixels); the
        coarse phase only makes the early, far-from-converged iterations cheaper.
        """
        steps = jnp.asarray(0)
        n_pix = problem.z.shape[-1]
        if self.coarse_stride > 1 and n_pix >= self.coarse_min_pixels:
            k = self.coarse_stride
            coarse = _coarse(problem, k)
            y_c, n_c, done_c, stuck_c, _ = self._lm_loop(coarse, y0, max_steps, self.coarse_tol_px, 0.0)
            y0 = jnp.where(done_c & ~stuck_c, y_c, y0)  # a failed coarse phase starts the fine one afresh
            steps = n_c
        y, n, done, stuck, normal = self._lm_loop(problem, y0, max_steps, self.atol, self.rtol)
        result = FitResult.where(
            done, FitResult.successful, FitResult.where(stuck, FitResult.diverged, FitResult.max_steps_reached)
        )
        return y, steps + n, _finish(problem, y, result), normal

    def _lm_loop(self, problem: LimbProblem, y0: Array, max_steps: int, atol: float, rtol: float):  # noqa: ANN202
        dtype = y0.dtype
        tiny = jnp.finfo(dtype).tiny

        def damped_step(jtj, jtr, lam):  # type: ignore[no-untyped-def]
            d = jnp.diagonal(jtj)
            scale = jnp.maximum(d, 1e-12 * jnp.max(d) + tiny)
            chol = jnp.linalg.cholesky(jtj + jnp.diag(lam * scale))
            h = -jax.scipy.linalg.cho_solve((chol, True), jtr)
            return h, lam * scale

        def body(c):  # type: ignore[no-untyped-def]
            y, jtj, jtr, rss, lam, nu, n, _, _ = c
            h, mu_d = damped_step(jtj, jtr, lam)
            y_try = y + h
            jtj_t, jtr_t, rss_t = problem.normal_equations(y_try)
            pred = 0.5 * (h @ (mu_d * h) - h @ jtr)  # L(0) - L(h) of the local model (> 0)
            gain = 0.5 * (rss - rss_t) / jnp.where(pred > 0, pred, 1.0)
            ok = jnp.isfinite(rss_t) & problem.admissible(y_try) & (pred > 0) & (gain > 0)
            small = jnp.max(jnp.abs(h)) <= atol + rtol * jnp.max(jnp.abs(y))
            y = jnp.where(ok, y_try, y)
            jtj = jnp.where(ok, jtj_t, jtj)
            jtr = jnp.where(ok, jtr_t, jtr)
            rss = jnp.where(ok, rss_t, rss)
            lam = jnp.where(ok, lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3), lam * nu)
            nu = jnp.where(ok, 2.0, 2.0 * nu)
            stuck = ~ok & (lam > 1e16)
            return y, jtj, jtr, rss, lam, nu, n + 1, small & jnp.all(jnp.isfinite(h)), stuck

        def cond(c):  # type: ignore[no-untyped-def]
            n, done, stuck = c[6], c[7], c[8]
            return (n < max_steps) & ~done & ~stuck

        jtj, jtr, rss = problem.normal_equations(y0)
        init = (y0, jtj, jtr, rss, jnp.asarray(self.lambda0, dtype), jnp.asarray(2.0, dtype),
                jnp.asarray(0), jnp.asarray(False), ~jnp.isfinite(rss))
        y, jtj, jtr, rss, _, _, n, done, stuck = jax.lax.while_loop(cond, body, init)
        return y, n, done, stuck, (jtj, jtr, rss)


def optimistix_normal_lm(rtol: float = 1e-10, atol: float = 1e-10, lambda0: float = 1e-3) -> Optimistix:
    """:class:`MarquardtCholeskyDescent` run by optimistix's ``AbstractGaussNewton`` + ``ClassicalTrustRegion``."""
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


# ============================================================================ paper
class PaperGaussNewton(AbstractLimbSolver):
    r"""The paper's iteration, Eq. (15) of Mortari, D'Souza & Zanetti (2016).

    .. math:: \Delta\theta = (\mathcal{J}^\top\mathcal{J})^{-1}\mathcal{J}^\top
              \{f_i - f(x_i)\},\qquad \theta \leftarrow \theta + \Delta\theta

    with the analytic Jacobian of Eq. (14)/(17) (or autodiff if the problem says
    so), undamped, until :math:`\max|\Delta\theta| \le atol + rtol\max|\theta|`.
    Undamped Gauss--Newton diverges for steep sigmoids (``k = 3``) started a few
    pixels off: the step overshoots where the model is flat, then the Jacobian
    vanishes.  Such runs end with ``FitResult.diverged``.

    With ``record_history=True`` the iterates are kept (``history`` in the
    result's stats), as printed in the paper's Table 1.
    """

    rtol: float = 1e-10
    atol: float = 1e-10

    def solve(self, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        y, n, result, _ = self.solve_with_history(problem, y0, max_steps, keep=False)
        return y, n, result

    def solve_with_history(self, problem: LimbProblem, y0: Array, max_steps: int, keep: bool = True):  # noqa: ANN201
        def body(carry):  # type: ignore[no-untyped-def]
            y, n, _, hist, bad = carry
            jtj, jtr, _ = problem.normal_equations(y)
            delta = -jnp.linalg.solve(jtj, jtr)
            y_new = y + delta
            bad = ~problem.admissible(y_new)
            y_new = jnp.where(bad, y, y_new)
            small = jnp.max(jnp.abs(delta)) <= self.atol + self.rtol * jnp.max(jnp.abs(y_new))
            hist = hist.at[n + 1].set(y_new) if keep else hist
            return y_new, n + 1, small, hist, bad

        def cond(carry):  # type: ignore[no-untyped-def]
            _, n, done, _, bad = carry
            return (n < max_steps) & ~done & ~bad

        hist = jnp.full((max_steps + 1 if keep else 1, y0.shape[0]), jnp.nan, y0.dtype).at[0].set(y0)
        y, n, done, hist, bad = jax.lax.while_loop(
            cond, body, (y0, jnp.asarray(0), jnp.asarray(False), hist, jnp.asarray(False))
        )
        result = FitResult.where(
            bad, FitResult.diverged, FitResult.where(done, FitResult.successful, FitResult.max_steps_reached)
        )
        return y, n, result, hist


# ============================================================================ scipy
class ScipyLeastSquares(AbstractLimbSolver):
    """Baseline: :func:`scipy.optimize.least_squares` with the paper's analytic Jacobian.

    ``method="lm"`` is MINPACK's QR-based Levenberg--Marquardt.  The residual and
    Jacobian are the same jit-compiled JAX functions the other solvers use,
    called from SciPy's Python loop.  Not jittable, not vmappable.
    """

    jittable: ClassVar[bool] = False
    method: str = eqx.field(static=True, default="lm")
    xtol: float = 1e-12
    ftol: float = 1e-12
    gtol: float = 1e-12

    def solve(self, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        from scipy.optimize import least_squares

        res_j, jac_j, ok_j = _scipy_callables(problem)
        args = problem.args
        sol = least_squares(
            lambda y: np.asarray(res_j(y, args)),
            np.asarray(y0, dtype=float),
            jac=lambda y: np.asarray(jac_j(y, args)),
            method=self.method,
            xtol=self.xtol,
            ftol=self.ftol,
            gtol=self.gtol,
            max_nfev=max_steps * (len(problem.free_idx) + 1) if self.method == "lm" else max_steps,
        )
        y = jnp.asarray(sol.x)
        if sol.status > 0 and bool(ok_j(y, args)):
            result = FitResult.successful
        elif sol.status == 0:
            result = FitResult.max_steps_reached
        else:
            result = FitResult.diverged
        return y, jnp.asarray(sol.njev if sol.njev is not None else sol.nfev), result


_SCIPY_CACHE: dict[Any, tuple[Callable, Callable, Callable]] = {}


def _scipy_callables(problem: LimbProblem):  # noqa: ANN202
    key = (problem.model.name, problem.free_idx, problem.analytic)
    if key not in _SCIPY_CACHE:
        res = problem.residual

        def jac(y, args):  # type: ignore[no-untyped-def]
            p = LimbProblem(problem.model, problem.free_idx, problem.analytic, *args)
            return p.jacobian(y)

        def ok(y, args):  # type: ignore[no-untyped-def]
            p = LimbProblem(problem.model, problem.free_idx, problem.analytic, *args)
            return p.admissible(y)

        _SCIPY_CACHE[key] = (jax.jit(res), jax.jit(jac), jax.jit(ok))
    return _SCIPY_CACHE[key]


# ============================================================================ names
SOLVERS: dict[str, Callable[[], AbstractLimbSolver]] = {
    "lm": NormalLM,
    "optx-lm": lambda: Optimistix(optx.LevenbergMarquardt(rtol=OPTX_RTOL, atol=OPTX_ATOL)),
    "optx-normal-lm": optimistix_normal_lm,
    "dogleg": lambda: Optimistix(optx.Dogleg(rtol=OPTX_RTOL, atol=OPTX_ATOL)),
    "gauss-newton": lambda: Optimistix(optx.GaussNewton(rtol=OPTX_RTOL, atol=OPTX_ATOL)),
    "bfgs": lambda: Optimistix(optx.BFGS(rtol=OPTX_RTOL, atol=OPTX_ATOL)),
    "paper": PaperGaussNewton,
    "scipy": ScipyLeastSquares,
}
"""Solver names accepted by the command line (``--solver NAME``) -> constructors."""


def solver_from_name(name: str) -> AbstractLimbSolver:
    """The solver registered under ``name`` (see :data:`SOLVERS`)."""
    from ..errors import LimbInputError

    try:
        return SOLVERS[name]()
    except KeyError:
        raise LimbInputError(f"`solver` must be one of {sorted(SOLVERS)}, got {name!r}") from None
