"""The least-squares problem behind every solver: residuals over the free parameters.

A problem is ``model`` + pixel coordinates + observed intensities + per-pixel
weights (0 for padded pixels) + the full parameter vector at which the fixed
parameters are held.  Solvers see only the free sub-vector ``y``:

.. math:: r_i(y) = w_i\\,(f(\\theta(y), x_i) - z_i), \\qquad
          \\theta(y) = \\theta_0 \\text{ with the free entries replaced by } y.

With ``analytic=True`` the model is wrapped in a :func:`jax.custom_jvp` whose
derivative is the paper's analytic Jacobian (Eq. 14, 17, Sec. V-C), so that
autodiff-based solvers (optimistix) use the paper's formulas instead of tracing
the model.

The module also holds what every solver shares: :class:`LimbProblem`, the :class:`FitResult`
enumeration and the :class:`AbstractLimbSolver` base (the solvers of :mod:`jaxlimb.fitting.solvers`
and the optimistix ones of :mod:`jaxlimb.fitting.optimistix_solvers` build on them).
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..models import LimbModel


def model_fn(model: LimbModel, analytic: bool) -> Callable[[Array, Array], Array]:
    """``f(theta_vector, coords) -> intensities``; with the analytic Jacobian as its JVP if asked.

    Parameters
    ----------
    model : LimbModel
        The limb model.
    analytic : bool
        Wrap the intensity in a :func:`jax.custom_jvp` whose tangent is ``model.jacobian`` (the paper's
        derivatives); ``False``: autodiff traces the intensity.

    Returns
    -------
    callable
        ``f(theta, coords) -> (n,)``, ``theta`` the full parameter vector ``(p,)`` in field order.
    """
    ptype = model.params_type

    def f(theta: Array, coords: Array) -> Array:
        return model.intensity(ptype.from_vector(theta), coords)

    if not analytic:
        return f

    @jax.custom_jvp
    def f_an(theta: Array, coords: Array) -> Array:
        return f(theta, coords)

    @f_an.defjvp
    def _f_an_jvp(primals, tangents):  # type: ignore[no-untyped-def]
        theta, coords = primals
        dtheta, _ = tangents  # coordinates are data: no derivative is propagated through them
        out = f(theta, coords)
        jac = model.jacobian(ptype.from_vector(theta), coords)
        return out, jac @ dtheta

    return f_an


def jacobian_fn(model: LimbModel, analytic: bool) -> Callable[[Array, Array], Array]:
    """``J(theta_vector, coords) -> (n, p)``: analytic (paper) or ``jax.jacfwd``.

    Parameters
    ----------
    model : LimbModel
        The limb model.
    analytic : bool
        ``model.jacobian`` (the paper's derivatives) or ``jax.jacfwd`` of the intensity.

    Returns
    -------
    callable
        ``J(theta, coords) -> (n, p)``, columns in field order.
    """
    ptype = model.params_type
    if analytic:
        return lambda theta, coords: model.jacobian(ptype.from_vector(theta), coords)
    f = model_fn(model, analytic=False)
    return jax.jacfwd(f, argnums=0)


def expand(theta0: Float[Array, " p"], free_idx: tuple[int, ...], y: Float[Array, " q"]) -> Array:
    """Full parameter vector: ``theta0`` with the free entries set to ``y``.

    Parameters
    ----------
    theta0 : jax.Array (p,)
        Full parameter vector (the fixed entries are kept).
    free_idx : tuple of int
        Indices of the free parameters.
    y : jax.Array (q,)
        Values of the free parameters, in the order of ``free_idx``.

    Returns
    -------
    jax.Array (p,)
        The full vector.
    """
    return theta0.at[jnp.asarray(free_idx)].set(y)


def residual_fn(model: LimbModel, free_idx: tuple[int, ...], analytic: bool):  # noqa: ANN201
    r"""``residual(y, args) -> (n,)`` with ``args = (theta0, coords, z, w)``.

    Parameters
    ----------
    model : LimbModel
        The limb model.
    free_idx : tuple of int
        Indices of the free parameters.
    analytic : bool
        As :func:`model_fn`.

    Returns
    -------
    callable
        ``residual(y, args)``: the weighted residuals :math:`w_i (f(\theta(y), x_i) - z_i)`, ``(n,)``.
    """
    f = model_fn(model, analytic)

    def residual(y: Array, args: tuple[Array, Array, Array, Array]) -> Array:
        theta0, coords, z, w = args
        return w * (f(expand(theta0, free_idx, y), coords) - z)

    return residual


def residual_and_jacobian_t(model: LimbModel, free_idx: tuple[int, ...]):  # noqa: ANN201
    r"""``parts(y, args) -> (r, J^T)``: the weighted residuals and the transposed analytic Jacobian in one pass.

    The pass :class:`~jaxlimb.fitting.NormalLM` makes over the pixels
    (:meth:`~jaxlimb.models.LimbModel.intensity_and_jacobian_columns`: the paper's Eq. 14/17 columns
    computed with the intensities).

    Parameters
    ----------
    model : LimbModel
        The limb model (its analytic columns are used).
    free_idx : tuple of int
        Indices of the free parameters.

    Returns
    -------
    callable
        ``parts(y, args)`` with ``args = (theta0, coords, z, w)``: ``r`` ``(n,)``,
        :math:`r_i = w_i (f(\theta(y), x_i) - z_i)`, and ``J^T`` ``(q, n)``, :math:`w_i\,\partial f_i/\partial y_j`.
    """
    ptype = model.params_type

    def parts(y: Array, args: tuple[Array, Array, Array, Array]) -> tuple[Array, Array]:
        theta0, coords, z, w = args
        params = ptype.from_vector(expand(theta0, free_idx, y))
        f, cols = model.intensity_and_jacobian_columns(params, coords)
        jt = jnp.stack([cols[i] for i in free_idx], axis=0) * w  # (q, n)
        return w * (f - z), jt

    return parts


def fused_residual_fn(model: LimbModel, free_idx: tuple[int, ...]):  # noqa: ANN201
    """``residual(y, args)`` as :func:`residual_fn` with the analytic Jacobian, fused.

    The residual is a :func:`jax.custom_jvp` whose primal pass computes the intensities and
    the Jacobian columns of the free parameters together
    (:meth:`~jaxlimb.models.LimbModel.intensity_and_jacobian_columns`, the pass
    :class:`~jaxlimb.fitting.NormalLM` uses) and whose tangent is ``J @ dy``.  Under
    ``jax.linearize`` (how optimistix's Gauss--Newton family builds its Jacobian operator) the
    columns are computed once per point and the linear map is a ``(n, q)`` matrix product --
    no trace through the model's formulas.

    Parameters
    ----------
    model : LimbModel
        The limb model (its analytic columns are used).
    free_idx : tuple of int
        Indices of the free parameters.

    Returns
    -------
    callable
        ``residual(y, args) -> (n,)``, ``args = (theta0, coords, z, w)``.
    """
    parts = residual_and_jacobian_t(model, free_idx)

    @jax.custom_jvp
    def residual(y: Array, args: tuple[Array, Array, Array, Array]) -> Array:
        return parts(y, args)[0]

    @residual.defjvp
    def _residual_jvp(primals, tangents):  # type: ignore[no-untyped-def]
        y, args = primals
        dy, _ = tangents  # the data (theta0, coords, z, w) carry no derivative
        r, jt = parts(y, args)
        return r, dy @ jt

    return residual


class FitResult(eqx.Enumeration):  # type: ignore[misc]
    """Outcome of a fit: the names of optimistix's results plus the limb-specific failures.

    Its own enumeration (not a subclass of ``optimistix.RESULTS``), so that the default path
    does not import optimistix; :class:`~jaxlimb.fitting.solvers.Optimistix` maps optimistix's
    results onto it by name (``fit_result``).
    """

    successful = ""
    max_steps_reached = "The maximum number of solver steps was reached. Try increasing `max_steps`."
    singular = "A linear solve returned non-finite output (a singular or near-singular system)."
    breakdown = "An iterative linear solve broke down."
    stagnation = "An iterative linear solve stagnated."
    conlim = "The condition number of the linear system exceeded the solver's limit."
    nonfinite_input = "A linear solve received non-finite input."
    nonlinear_max_steps_reached = "The maximum number of steps was reached in the nonlinear solver."
    nonlinear_divergence = "The nonlinear solve diverged."
    solver_failed = "The optimistix solver reported a failure that has no name here."

    diverged = (
        "The fit diverged (non-finite parameters, or radius / semi-axis / k left the "
        "admissible range > 0). Start closer to the limb (e.g. from a Taubin circle) "
        "or use a damped solver (NormalLM, LevenbergMarquardt, Dogleg)."
    )


class LimbProblem(eqx.Module):
    r"""A limb least-squares problem (one image, or one member of a vmapped batch).

    Attributes
    ----------
    model : the sigmoid model (static).
    free_idx : indices of the free parameters in the model's parameter vector (static).
    analytic : use the paper's analytic Jacobian (True) or autodiff (False) (static).
    theta0 : full parameter vector; its fixed entries are held, its free ones are the start.
    coords : pixel coordinates, ``(n, 2)`` ``(row, col)`` (or ``(n,)`` for the linear model).
    z : observed intensities ``(n,)``.
    w : per-pixel weights ``(n,)``: 1 for data, 0 for padding (or 1/sigma_i).
    mask : optional 0/1 flags of the free parameters ``(q,)``: a 0 holds that parameter at its
        start for this problem only (its Jacobian row and step are zero, its diagonal of
        :math:`J^\top J` is 1: the normal equations of the other parameters are those of the
        problem without it), so that fits which differ only in what they hold share one compiled
        program.  ``None``: every free parameter is estimated.
    """

    model: LimbModel = eqx.field(static=True)
    free_idx: tuple[int, ...] = eqx.field(static=True)
    analytic: bool = eqx.field(static=True)
    theta0: Float[Array, " p"]
    coords: Array
    z: Float[Array, " n"]
    w: Float[Array, " n"]
    mask: Float[Array, " q"] | None = None

    @property
    def args(self) -> tuple[Array, Array, Array, Array]:
        return (self.theta0, self.coords, self.z, self.w)

    @property
    def residual(self) -> Callable[[Array, Any], Array]:
        return residual_fn(self.model, self.free_idx, self.analytic)

    def jacobian(self, y: Array) -> Float[Array, "n q"]:
        r"""Weighted Jacobian of the residuals w.r.t. the free parameters.

        Parameters
        ----------
        y : jax.Array (q,)
            Free parameters.

        Returns
        -------
        jax.Array (n, q)
            :math:`w_i\,\partial f_i/\partial y_j`.
        """
        jf = jacobian_fn(self.model, self.analytic)
        full = jf(expand(self.theta0, self.free_idx, y), self.coords)
        return self.w[:, None] * full[:, jnp.asarray(self.free_idx)]

    def normal_equations(self, y: Array) -> tuple[Array, Array, Array]:
        r"""``(J^T J, J^T r, r^T r)`` over the free parameters in one fused pass.

        The Jacobian is built transposed, ``(q, n)``, which on CPU is ~2x
        faster than the ``(n, q)`` layout for these reductions.

        Parameters
        ----------
        y : jax.Array (q,)
            Free parameters.

        Returns
        -------
        jtj : jax.Array (q, q)
            :math:`J^\top J` (a held parameter's row and column are those of the identity).
        jtr : jax.Array (q,)
            :math:`J^\top r`.
        rss : jax.Array ()
            :math:`r^\top r`, the weighted residual sum of squares.
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
        if self.mask is None:
            return jt @ jt.T, jt @ r, r @ r
        on = self.mask > 0
        jt = jnp.where(on[:, None], jt, 0.0)  # a held parameter's row: exactly 0 (even if not finite)
        return jt @ jt.T + jnp.diag(jnp.where(on, 0.0, 1.0)), jt @ r, r @ r

    @property
    def n_free(self) -> Any:
        """Number of estimated parameters (``q``, or the count of the mask's ones)."""
        return len(self.free_idx) if self.mask is None else jnp.sum(self.mask > 0)

    def estimated(self, y: Array) -> Array:
        """``y`` with its held entries (``mask`` 0) set to 0: the scale of the convergence test.

        Parameters
        ----------
        y : jax.Array (q,)
            Free parameters.

        Returns
        -------
        jax.Array (q,)
            ``y``, held entries zeroed.
        """
        return y if self.mask is None else jnp.where(self.mask > 0, y, 0.0)

    def admissible(self, y: Array) -> Bool[Array, ""]:
        """Finite, and every scale parameter (radius, a, k, rho) strictly positive.

        Parameters
        ----------
        y : jax.Array (q,)
            Free parameters.

        Returns
        -------
        jax.Array () of bool
            Whether the full parameter vector is admissible.
        """
        theta = expand(self.theta0, self.free_idx, y)
        ok = jnp.all(jnp.isfinite(theta))
        for i, name in enumerate(self.model.param_names):
            if name in _POSITIVE:
                ok = ok & (theta[i] > 0)
        return ok


_POSITIVE = frozenset({"radius", "a", "k", "rho"})


class AbstractLimbSolver(eqx.Module):
    """Base class of the solvers behind :func:`jaxlimb.fitting.fit`."""

    jittable: ClassVar[bool] = True
    masks: ClassVar[bool] = False
    """Whether :meth:`solve` honours :class:`LimbProblem`'s ``mask`` and takes ``max_steps`` as an array."""

    @abc.abstractmethod
    def solve(
        self, problem: LimbProblem, y0: Float[Array, " q"], max_steps: int
    ) -> tuple[Float[Array, " q"], Int[Array, ""], FitResult]:
        """Solve the least-squares problem for the free parameters.

        Parameters
        ----------
        problem : LimbProblem
            The problem.
        y0 : jax.Array (q,)
            Start of the free parameters.
        max_steps : int
            Iteration limit (a scalar array for solvers with :attr:`masks`).

        Returns
        -------
        y : jax.Array (q,)
            The estimate.
        n_steps : jax.Array () of int
            Iterations taken.
        result : FitResult
            ``successful`` only if converged to an admissible point.
        """

    @property
    def name(self) -> str:
        return type(self).__name__


def finish_result(problem: LimbProblem, y: Array, result: FitResult) -> FitResult:
    """``result``, or ``diverged`` where a solver reports success at an inadmissible point.

    Parameters
    ----------
    problem : LimbProblem
        The problem that was solved.
    y : jax.Array (q,)
        The solver's answer.
    result : FitResult
        The solver's own outcome.

    Returns
    -------
    FitResult
        The outcome to report.
    """
    return FitResult.where(
        (result == FitResult.successful) & ~problem.admissible(y), FitResult.diverged, result
    )


def coarse_problem(problem: LimbProblem, k: int) -> LimbProblem:
    """Every ``k``-th pixel of ``problem`` (the coarse phase of coarse-to-fine).

    Parameters
    ----------
    problem : LimbProblem
        The full problem.
    k : int
        Stride over the pixels.

    Returns
    -------
    LimbProblem
        The same problem on ``ceil(n / k)`` pixels.
    """
    return LimbProblem(problem.model, problem.free_idx, problem.analytic, problem.theta0,
                       problem.coords[::k], problem.z[::k], problem.w[::k], problem.mask)


def result_names(result: FitResult | Any) -> list[str]:
    """The names (``"successful"``, ``"diverged"``, ...) of a batch of :class:`FitResult` values (or of their codes).

    Parameters
    ----------
    result : FitResult or array_like of int
        One or a batch of results, or their integer codes.

    Returns
    -------
    list of str
        One name per member (``"unknown"`` for a code that is not a :class:`FitResult`).
    """
    codes = np.atleast_1d(np.asarray(getattr(result, "_value", result)))
    names = {int(np.asarray(item._value)): name for name, item in FitResult._name_to_item.items()}
    return [names.get(int(c), "unknown") for c in codes]
