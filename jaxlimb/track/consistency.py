r"""Filter consistency and the bound the estimates are held to.

* NEES ``(x - x_true)^T P^-1 (x - x_true)`` and NIS (:mod:`jaxlimb.track.filter`); over ``N`` independent
  runs the average of a consistent filter's NEES of an ``n``-vector is ``chi2(N n) / N``: the two-sided 95 %
  band is ``[chi2.ppf(0.025, N n), chi2.ppf(0.975, N n)] / N`` (Bar-Shalom, Li & Kirubarajan 2001, §5.4).
* Posterior Cramér--Rao bound of the smoothed states for deterministic dynamics (the truth has no process
  noise): the information on the state at ``t0`` is ``J0 = P0^-1 + sum_k Phi_k^T H_k^T R_k^-1 H_k Phi_k`` with
  ``Phi_k``, ``H_k`` evaluated along the true trajectory (Tichavský, Muravchik & Nehorai 1998, IEEE TSP 46(5),
  Eq. 21 with no process noise) and the bound at ``t_k`` is ``Phi_k J0^-1 Phi_k^T``.  With bias states
  (:mod:`jaxlimb.track.bias`) the unknowns are ``(x0, b)``: ``Phi_k`` gains the identity on ``b``, ``H_k`` the
  columns ``dh/db`` at ``b = 0``, ``J0`` the prior ``diag(sigma^-2)``, and the bound is the ``x`` block of its
  inverse (the biases unknown).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from scipy.stats import chi2

from .bias import BiasModel, bias_model
from .dynamics import Propagator
from .filter import measurement_function
from .measurement import Frames, total_covariance


def nees(x: np.ndarray, P: np.ndarray, x_true: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared of each row of ``x`` ``(..., n)`` with covariances ``P``."""
    e = np.asarray(x) - np.asarray(x_true)
    return np.einsum("...i,...i->...", e, np.linalg.solve(P, e[..., None])[..., 0])


def average_band(n_runs: int, dof: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided ``probability`` band of the ``n_runs``-run average of a ``chi2(dof)`` statistic."""
    a = (1.0 - probability) / 2.0
    return float(chi2.ppf(a, n_runs * dof) / n_runs), float(chi2.ppf(1.0 - a, n_runs * dof) / n_runs)


def posterior_crlb(frames: Frames, prop: Propagator, x0_true: np.ndarray, t0: float, P0: np.ndarray,
                   theta: np.ndarray | None = None, bias: bool | BiasModel = True) -> np.ndarray:
    """Posterior Cramér--Rao bound (n, 6, 6) of the states at the frames (module docstring); ``theta`` the true
    camera (default: the frames' own); ``bias`` as :func:`~jaxlimb.track.filter.run_filter`'s."""
    ts = jnp.asarray(frames.t)

    def traj(x):  # noqa: ANN001, ANN202
        return prop.trajectory(x, jnp.asarray(float(t0)), ts)

    x0 = jnp.asarray(x0_true, float)
    X = traj(x0)
    Phi = np.asarray(jax.jacfwd(traj)(x0))
    th = jnp.asarray(frames.theta if theta is None else np.broadcast_to(theta, frames.theta.shape))
    args = frames.arrays()
    bm = bias if isinstance(bias, BiasModel) else bias_model(frames, bool(bias))
    nb = len(bm)
    sun = jnp.asarray(frames.sun_pos if frames.sun_pos is not None else np.zeros((len(frames), 3)))
    Xa = jnp.concatenate([X, jnp.zeros((X.shape[0], nb))], 1)

    def jac(x, th_, s, E, *a):  # noqa: ANN001, ANN202
        return jax.jacfwd(measurement_function(th_, a, s, E))(x)

    H = np.asarray(jax.vmap(jac)(Xa, th, sun, jnp.asarray(bm.select), *args))
    Rt = np.asarray(jax.vmap(total_covariance)(X[:, :3], th, jnp.asarray(frames.R), jnp.asarray(frames.attitude_sigma), *args))
    G = np.concatenate([np.einsum("kij,kjl->kil", H[:, :, :6], Phi), H[:, :, 6:]], 2)
    prior = np.zeros((6 + nb, 6 + nb))
    prior[:6, :6] = np.linalg.inv(P0)
    prior[6:, 6:] = np.diag(bm.sigma**-2.0)
    J0 = prior + np.einsum("kji,kjl,klm->im", G, np.linalg.inv(Rt), G)
    return np.einsum("kij,jl,kml->kim", Phi, np.linalg.inv(J0)[:6, :6], Phi)


__all__ = ["average_band", "nees", "posterior_crlb"]
