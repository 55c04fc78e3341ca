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

from collections.abc import Callable
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
from jaxtyping import Array

from .problem import AbstractLimbSolver, FitResult, LimbProblem, coarse_problem, finish_result
from .scipy_solver import ScipyLeastSquares


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

    masks: ClassVar[bool] = True
    rtol: float = 1e-10
    atol: float = 1e-10
    lambda0: float = 1e-3
    coarse_stride: int = 4
    coarse_tol_px: float = 1e-2
    coarse_min_pixels: int = 1024

    def solve(self, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        """Run the iteration (:meth:`solve_normal` without the normal equations).

        Parameters
        ----------
        problem : LimbProblem
            The problem (its ``mask`` is honoured).
        y0 : jax.Array (q,)
            Start of the free parameters.
        max_steps : int or jax.Array ()
            Iteration limit (coarse and fine phases each).

        Returns
        -------
        y : jax.Array (q,)
            The estimate.
        n_steps : jax.Array () of int
            Iterations of both phases.
        result : FitResult
            ``successful``, ``max_steps_reached`` or ``diverged``.
        """
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

        Parameters
        ----------
        problem : LimbProblem
            The problem (its ``mask`` is honoured).
        y0 : jax.Array (q,)
            Start of the free parameters.
        max_steps : int or jax.Array ()
            Iteration limit (coarse and fine phases each).

        Returns
        -------
        y, n_steps, result
            As :meth:`solve`.
        normal : tuple of jax.Array
            ``(J^T J, J^T r, r^T r)`` at ``y`` (:meth:`~jaxlimb.fitting.LimbProblem.normal_equations`).
        """
        steps = jnp.asarray(0)
        n_pix = problem.z.shape[-1]
        if self.coarse_stride > 1 and n_pix >= self.coarse_min_pixels:
            k = self.coarse_stride
            coarse = coarse_problem(problem, k)
            y_c, n_c, done_c, stuck_c, _ = self._lm_loop(coarse, y0, max_steps, self.coarse_tol_px, 0.0)
            y0 = jnp.where(done_c & ~stuck_c, y_c, y0)  # a failed coarse phase starts the fine one afresh
            steps = n_c
        y, n, done, stuck, normal = self._lm_loop(problem, y0, max_steps, self.atol, self.rtol)
        result = FitResult.where(
            done, FitResult.successful, FitResult.where(stuck, FitResult.diverged, FitResult.max_steps_reached)
        )
        return y, steps + n, finish_result(problem, y, result), normal

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
            y, jtj, jtr, rss, lam, nu, n, _, _, first = c
            h, mu_d = damped_step(jtj, jtr, lam)
            y_try = jnp.where(first, y, y + h)  # the first pass evaluates the start itself
            jtj_t, jtr_t, rss_t = problem.normal_equations(y_try)
            pred = 0.5 * (h @ (mu_d * h) - h @ jtr)  # L(0) - L(h) of the local model (> 0)
            gain = 0.5 * (rss - rss_t) / jnp.where(pred > 0, pred, 1.0)
            ok = first | (jnp.isfinite(rss_t) & problem.admissible(y_try) & (pred > 0) & (gain > 0))
            small = jnp.max(jnp.abs(h)) <= atol + rtol * jnp.max(jnp.abs(problem.estimated(y)))
            y = jnp.where(ok, y_try, y)
            jtj = jnp.where(ok, jtj_t, jtj)
            jtr = jnp.where(ok, jtr_t, jtr)
            rss = jnp.where(ok, rss_t, rss)
            lam_new = jnp.where(ok, lam * jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3), lam * nu)
            nu_new = jnp.where(ok, 2.0, 2.0 * nu)
            stuck = jnp.where(first, ~jnp.isfinite(rss_t), ~ok & (lam_new > 1e16))
            done = ~first & small & jnp.all(jnp.isfinite(h))
            return (y, jtj, jtr, rss, jnp.where(first, lam, lam_new), jnp.where(first, nu, nu_new),
                    n + jnp.where(first, 0, 1), done, stuck, jnp.asarray(False))

        def cond(c):  # type: ignore[no-untyped-def]
            n, done, stuck, first = c[6], c[7], c[8], c[9]
            return first | ((n < max_steps) & ~done & ~stuck)

        # one model pass in the program (the loop's): the start is evaluated by its first pass, where
        # the placeholder normal equations (I, 0, inf) give a zero step
        q = y0.shape[-1]
        init = (y0, jnp.eye(q, dtype=dtype), jnp.zeros(q, dtype), jnp.asarray(jnp.inf, dtype),
                jnp.asarray(self.lambda0, dtype), jnp.asarray(2.0, dtype), jnp.asarray(0), jnp.asarray(False),
                jnp.asarray(False), jnp.asarray(True))
        y, jtj, jtr, rss, _, _, n, done, stuck, _ = jax.lax.while_loop(cond, body, init)
        return y, n, done, stuck, (jtj, jtr, rss)



# ============================================================================ optimistix (lazy)
_LAZY = frozenset({"Optimistix", "optimistix_normal_lm", "MarquardtCholeskyDescent", "OPTX_RTOL", "OPTX_ATOL", "fit_result",
                   "ScaledBFGS"})


def __getattr__(name: str) -> Any:
    """The optimistix solvers live in :mod:`jaxlimb.fitting.optimistix_solvers`, imported on first use (PEP 562):
    the default path (:class:`NormalLM`) never pays for importing optimistix and lineax."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(".optimistix_solvers", __package__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _optx_solver(kind: str) -> Callable[[], AbstractLimbSolver]:
    """optimistix's ``kind``: the Gauss--Newton family with :class:`NormalLM`'s stopping rule and tolerances
    (``StepStop``), BFGS (:class:`~jaxlimb.fitting.optimistix_solvers.ScaledBFGS`: started at the loss's scale)
    with its own Cauchy test at ``OPTX_RTOL``/``OPTX_ATOL``."""

    def make() -> AbstractLimbSolver:
        import optimistix as optx

        from .optimistix_solvers import OPTX_ATOL, OPTX_RTOL, Optimistix, ScaledBFGS

        cls = ScaledBFGS if kind == "BFGS" else getattr(optx, kind)
        if issubclass(cls, optx.AbstractGaussNewton):
            return Optimistix(cls(rtol=NormalLM.rtol, atol=NormalLM.atol))
        return Optimistix(cls(rtol=OPTX_RTOL, atol=OPTX_ATOL))

    return make


def _optimistix_normal_lm() -> AbstractLimbSolver:
    from .optimistix_solvers import optimistix_normal_lm

    return optimistix_normal_lm()


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
        """Run Eq. (15) from ``y0`` (:meth:`solve_with_history` without the iterates).

        Parameters
        ----------
        problem : LimbProblem
            The problem.
        y0 : jax.Array (q,)
            Start of the free parameters.
        max_steps : int
            Iteration limit.

        Returns
        -------
        y : jax.Array (q,)
            The estimate (the last admissible iterate).
        n_steps : jax.Array () of int
            Iterations taken.
        result : FitResult
            ``successful``, ``max_steps_reached`` or ``diverged`` (an inadmissible step).
        """
        y, n, result, _ = self.solve_with_history(problem, y0, max_steps, keep=False)
        return y, n, result

    def solve_with_history(self, problem: LimbProblem, y0: Array, max_steps: int, keep: bool = True):  # noqa: ANN201
        """As :meth:`solve`, also returning the iterates (the paper's Table 1).

        Parameters
        ----------
        problem : LimbProblem
            The problem.
        y0 : jax.Array (q,)
            Start of the free parameters.
        max_steps : int
            Iteration limit (a Python int: it sizes the history).
        keep : bool
            Record the iterates; ``False`` keeps only ``y0``.

        Returns
        -------
        y, n_steps, result
            As :meth:`solve`.
        history : jax.Array (max_steps + 1, q)
            ``y0`` and the iterates, NaN after the last (``(1, q)`` without ``keep``).
        """
        def body(carry):  # type: ignore[no-untyped-def]
            y, n, _, hist, bad = carry
            jtj, jtr, _ = problem.normal_equations(y)
            delta = -jnp.linalg.solve(jtj, jtr)
            y_new = y + delta
            bad = ~problem.admissible(y_new)
            y_new = jnp.where(bad, y, y_new)
            small = jnp.max(jnp.abs(delta)) <= self.atol + self.rtol * jnp.max(jnp.abs(problem.estimated(y_new)))
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


# ============================================================================ names
SOLVERS: dict[str, Callable[[], AbstractLimbSolver]] = {
    "lm": NormalLM,
    "optx-lm": _optx_solver("LevenbergMarquardt"),
    "optx-normal-lm": _optimistix_normal_lm,
    "dogleg": _optx_solver("Dogleg"),
    "gauss-newton": _optx_solver("GaussNewton"),
    "bfgs": _optx_solver("BFGS"),
    "paper": PaperGaussNewton,
    "scipy": ScipyLeastSquares,
}
"""Solver names accepted by the command line (``--solver NAME``) -> constructors."""


def solver_from_name(name: str) -> AbstractLimbSolver:
    """The solver registered under ``name`` (see :data:`SOLVERS`).

    Parameters
    ----------
    name : str
        A key of :data:`SOLVERS` (``"lm"``, ``"optx-lm"``, ``"paper"``, ``"scipy"``, ...).

    Returns
    -------
    AbstractLimbSolver
        A new solver with its default settings.

    Raises
    ------
    LimbInputError
        ``name`` is not registered.
    """
    from ..errors import LimbInputError

    try:
        return SOLVERS[name]()
    except KeyError:
        raise LimbInputError(f"`solver` must be one of {sorted(SOLVERS)}, got {name!r}") from None
