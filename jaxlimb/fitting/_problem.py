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
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..models import LimbModel


def model_fn(model: LimbModel, analytic: bool) -> Callable[[Array, Array], Array]:
    """``f(theta_vector, coords) -> intensities``; with the analytic Jacobian as its JVP if asked."""
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
    """``J(theta_vector, coords) -> (n, p)``: analytic (paper) or ``jax.jacfwd``."""
    ptype = model.params_type
    if analytic:
        return lambda theta, coords: model.jacobian(ptype.from_vector(theta), coords)
    f = model_fn(model, analytic=False)
    return jax.jacfwd(f, argnums=0)


def expand(theta0: Float[Array, " p"], free_idx: tuple[int, ...], y: Float[Array, " q"]) -> Array:
    """Full parameter vector: ``theta0`` with the free entries set to ``y``."""
    return theta0.at[jnp.asarray(free_idx)].set(y)


def residual_fn(model: LimbModel, free_idx: tuple[int, ...], analytic: bool):  # noqa: ANN201
    """``residual(y, args) -> (n,)`` with ``args = (theta0, coords, z, w)``."""
    f = model_fn(model, analytic)

    def residual(y: Array, args: tuple[Array, Array, Array, Array]) -> Array:
        theta0, coords, z, w = args
        return w * (f(expand(theta0, free_idx, y), coords) - z)

    return residual


def fused_residual_fn(model: LimbModel, free_idx: tuple[int, ...]):  # noqa: ANN201
    """``residual(y, args)`` as :func:`residual_fn` with the analytic Jacobian, fused.

    The residual is a :func:`jax.custom_jvp` whose primal pass computes the intensities and
    the Jacobian columns of the free parameters together
    (:meth:`~jaxlimb.models.LimbModel.intensity_and_jacobian_columns`, the pass
    :class:`~jaxlimb.fitting.NormalLM` uses) and whose tangent is ``J @ dy``.  Under
    ``jax.linearize`` (how optimistix's Gauss--Newton family builds its Jacobian operator) the
    columns are computed once per point and the linear map is a ``(n, q)`` matrix product --
    no trace through the model's formulas.
    """
    ptype = model.params_type

    def parts(y: Array, args: tuple[Array, Array, Array, Array]) -> tuple[Array, Array]:
        theta0, coords, z, w = args
        params = ptype.from_vector(expand(theta0, free_idx, y))
        f, cols = model.intensity_and_jacobian_columns(params, coords)
        jt = jnp.stack([cols[i] for i in free_idx], axis=0) * w  # (q, n)
        return w * (f - z), jt

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
