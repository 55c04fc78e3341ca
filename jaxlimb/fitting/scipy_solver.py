r"""The SciPy baseline: :func:`scipy.optimize.least_squares` (MINPACK's Levenberg--Marquardt) on the limb problem.

The residual and the Jacobian reach SciPy as host arrays from one compiled JAX call per point
(:func:`~jaxlimb.fitting.problem.residual_and_jacobian_t`: the paper's analytic Jacobian computed in the
same pass over the pixels as the residuals, the pass the default solver makes).  MINPACK asks for the
Jacobian at points whose residuals it has just evaluated, so each point costs one call; the transposed
Jacobian ``(q, n)`` is handed over as the column-major ``(n, q)`` array MINPACK works on, without a copy.
The compiled calls are kept per model and free set: no tracing after the first fit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..numerics import one_blas_thread
from .problem import AbstractLimbSolver, FitResult, LimbProblem, residual_and_jacobian_t


class ScipyLeastSquares(AbstractLimbSolver):
    """Baseline: :func:`scipy.optimize.least_squares` with the paper's analytic Jacobian.

    ``method="lm"`` is MINPACK's QR-based Levenberg--Marquardt with its own variable scaling by the
    Jacobian's column norms (``x_scale="jac"``, MINPACK's ``mode = 1``).  The residual and Jacobian are
    the jit-compiled JAX functions of the other solvers, called from SciPy's loop (module docstring).
    Not jittable, not vmappable.
    """

    jittable: ClassVar[bool] = False
    method: str = eqx.field(static=True, default="lm")
    xtol: float = 1e-12
    ftol: float = 1e-12
    gtol: float = 1e-12

    def solve(self, problem, y0, max_steps):  # type: ignore[no-untyped-def]
        """Run :func:`scipy.optimize.least_squares` from ``y0`` (on the host, not jittable).

        Parameters
        ----------
        problem : LimbProblem
            The problem.
        y0 : jax.Array (q,)
            Start of the free parameters.
        max_steps : int
            Iteration limit; SciPy's ``max_nfev`` is ``max_steps (q + 1)`` for ``method="lm"``.

        Returns
        -------
        y : jax.Array (q,)
            The estimate.
        n_steps : jax.Array () of int
            Jacobian evaluations (function evaluations if SciPy does not report them).
        result : FitResult
            ``successful`` (converged and admissible), ``max_steps_reached`` or ``diverged``.
        """
        from scipy.optimize import least_squares

        parts, ok_j = scipy_callables(problem)
        host = HostResidual(parts, problem.args)
        with one_blas_thread():
            sol = least_squares(
                host.residual,
                np.asarray(y0, dtype=float),
                jac=host.jacobian,
                method=self.method,
                x_scale="jac",
                xtol=self.xtol,
                ftol=self.ftol,
                gtol=self.gtol,
                max_nfev=max_steps * (len(problem.free_idx) + 1) if self.method == "lm" else max_steps,
            )
        y = jnp.asarray(sol.x)
        if sol.status > 0 and bool(ok_j(y, problem.args)):
            result = FitResult.successful
        elif sol.status == 0:
            result = FitResult.max_steps_reached
        else:
            result = FitResult.diverged
        return y, jnp.asarray(sol.njev if sol.njev is not None else sol.nfev), result


class HostResidual:
    """Residuals and Jacobian of one problem as host arrays, one compiled call per point.

    ``parts(y, args) -> (r, J^T)`` runs once for each new ``y``; the Jacobian of a point whose residuals were
    evaluated (the last two points: MINPACK's trial and its last accepted point) comes from that call.

    Parameters
    ----------
    parts : callable
        The compiled ``parts(y, args)`` of :func:`scipy_callables`.
    args : tuple
        ``(theta0, coords, z, w)`` of the problem, on the device.
    """

    def __init__(self, parts: Callable[..., Any], args: tuple[Any, ...]) -> None:
        self._parts, self._args = parts, args
        self._points: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def _at(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = np.asarray(y, dtype=float).tobytes()
        if key not in self._points:
            r, jt = jax.device_get(self._parts(np.asarray(y, dtype=float), self._args))
            if len(self._points) >= 2:
                self._points.pop(next(iter(self._points)))
            self._points[key] = (r, jt.T)  # (n, q), column-major: MINPACK's layout
        return self._points[key]

    def residual(self, y: np.ndarray) -> np.ndarray:
        """The weighted residuals ``(n,)`` at ``y``.

        Parameters
        ----------
        y : numpy.ndarray
            The free parameters ``(q,)`` in the solver's scaled coordinates.

        Returns
        -------
        numpy.ndarray
            The weighted residuals ``(n,)``.
        """
        return self._at(y)[0]

    def jacobian(self, y: np.ndarray) -> np.ndarray:
        """The weighted Jacobian ``(n, q)`` at ``y`` (column-major).

        Parameters
        ----------
        y : numpy.ndarray
            The free parameters ``(q,)`` in the solver's scaled coordinates.

        Returns
        -------
        numpy.ndarray
            The Jacobian ``(n, q)`` of the weighted residuals, in Fortran (column-major) order.
        """
        return self._at(y)[1]


_SCIPY_CACHE: dict[Any, tuple[Callable, Callable]] = {}


def scipy_callables(problem: LimbProblem) -> tuple[Callable, Callable]:
    """The compiled ``parts(y, args) -> (r, J^T)`` and ``admissible(y, args)`` of ``problem``'s model and free set.

    Analytic: :func:`~jaxlimb.fitting.problem.residual_and_jacobian_t`; otherwise the residual and
    ``jax.jacfwd`` of it.  Kept per ``(model, free_idx, analytic)``: every later problem of the same shape
    reuses the compiled programs.

    Parameters
    ----------
    problem : LimbProblem
        Any problem of the model and free set.

    Returns
    -------
    parts, admissible : callable
        ``jax.jit``-compiled functions of ``(y, args)``.
    """
    key = (problem.model, problem.free_idx, problem.analytic)
    if key not in _SCIPY_CACHE:
        model, free_idx, analytic = key
        if analytic:
            parts = residual_and_jacobian_t(model, free_idx)
        else:
            res = problem.residual

            def parts(y, args):  # type: ignore[no-untyped-def]
                return res(y, args), jax.jacfwd(res)(y, args).T

        def ok(y, args):  # type: ignore[no-untyped-def]
            return LimbProblem(model, free_idx, analytic, *args).admissible(y)

        _SCIPY_CACHE[key] = (jax.jit(parts), jax.jit(ok))
    return _SCIPY_CACHE[key]


__all__ = ["HostResidual", "ScipyLeastSquares", "scipy_callables"]
