r"""Filter consistency and the bound the estimates are held to.

* NEES ``(x - x_true)^T P^-1 (x - x_true)`` and NIS (:mod:`jaxlimb.track.filter`); over ``N`` independent
  runs the average of a consistent filter's NEES of an ``n``-vector is ``chi2(N n) / N``: the two-sided 95 %
  band is ``[chi2.ppf(0.025, N n), chi2.ppf(0.975, N n)] / N`` (Bar-Shalom, Li & Kirubarajan 2001, §5.4).
* Posterior Cramér--Rao bound of the smoothed states for deterministic dynamics (the truth has no process
  noise): the information on the state at ``t0`` is ``J0 = P0^-1 + sum_k Phi_k^T H_k^T R_k^-1 H_k Phi_k`` with
  ``Phi_k``, ``H_k`` evaluated along the true trajectory (Tichavský, Muravchik & Nehorai 1998, IEEE TSP 46(5),
  Eq. 21 with no process noise) and the bound at ``t_k`` is ``Phi_k J0^-1 Phi_k^T``.  With bias states
  (:mod:`jaxlimb.track.bias`: a constant and, when they walk, a random walk) the biases are Gaussian nuisance
  effects ``W u`` (:func:`~jaxlimb.track.bias.random_effects`) marginalised out of the information:
  ``sum_k G_k^T R_k^-1 G_k`` becomes ``G^T (D + W W^T)^-1 G`` (``G_k = H_k Phi_k``, ``D = blockdiag(R_k)``),
  computed with Woodbury's identity.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy.stats import chi2

from .bias import BiasModel, bias_model, random_effects
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


@dataclass(frozen=True)
class Linearisation:
    """The arc's measurement model linearised about a trajectory (:func:`linearise`).

    Attributes
    ----------
    Phi : (n, 6, 6) state transition from ``t0`` to each frame.
    r : (n, 3) residual ``z - h`` with no bias.
    G : (n, 3, 6) ``dh/dx0`` (through ``Phi``).
    E : (n, 3, n_b) ``dh/db`` at ``b = 0``.
    A : (n, 3, 3) the attitude term of the measurement covariance (:func:`~jaxlimb.track.measurement.total_covariance`).
    """

    Phi: np.ndarray
    r: np.ndarray
    G: np.ndarray
    E: np.ndarray
    A: np.ndarray


def linearise(frames: Frames, prop: Propagator, x0: np.ndarray, t0: float, bias: BiasModel,
              theta: np.ndarray | None = None) -> Linearisation:
    """The measurement model of ``frames`` linearised about the trajectory from ``x0`` at ``t0`` (autodiff through
    the dynamics and the camera), with the bias columns of ``bias`` and the camera ``theta`` (default the frames')."""
    ts = jnp.asarray(frames.t)

    def traj(x):  # noqa: ANN001, ANN202
        return prop.trajectory(x, jnp.asarray(float(t0)), ts)

    x0 = jnp.asarray(x0, float)
    Phi = np.asarray(jax.jacfwd(traj)(x0))
    h, H, A = measurement_jacobians(frames, np.asarray(traj(x0)), bias, theta)
    return Linearisation(Phi, frames.z - h, np.einsum("kij,kjl->kil", H[:, :, :6], Phi), H[:, :, 6:], A)


def measurement_jacobians(frames: Frames, X: np.ndarray, bias: BiasModel,
                          theta: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At the states ``X`` (n, 6) of the frames: the predicted measurements ``h`` (n, 3) with no bias, their
    Jacobian ``H`` (n, 3, 6 + n_b) over ``(r, v, b)`` and the attitude term ``A`` (n, 3, 3) of their covariance."""
    th = jnp.asarray(frames.theta if theta is None else np.broadcast_to(theta, frames.theta.shape))
    args = frames.arrays()
    sun = jnp.asarray(frames.sun_pos if frames.sun_pos is not None else np.zeros((len(frames), 3)))
    X = jnp.asarray(X, float)
    Xa = jnp.concatenate([X, jnp.zeros((X.shape[0], len(bias)))], 1)

    def h_and_jac(x, th_, s, E, *a):  # noqa: ANN001, ANN202
        h = measurement_function(th_, a, s, E)
        return h(x), jax.jacfwd(h)(x)

    h, H = (np.asarray(v) for v in jax.vmap(h_and_jac)(Xa, th, sun, jnp.asarray(bias.select), *args))
    A = np.asarray(jax.vmap(total_covariance)(X[:, :3], th, jnp.zeros((len(frames), 3, 3)),
                                              jnp.asarray(frames.attitude_sigma), *args))
    return h, H, A


def posterior_crlb(frames: Frames, prop: Propagator, x0_true: np.ndarray, t0: float, P0: np.ndarray,
                   theta: np.ndarray | None = None, bias: bool | BiasModel = True) -> np.ndarray:
    """Posterior Cramér--Rao bound (n, 6, 6) of the states at the frames (module docstring); ``theta`` the true
    camera (default: the frames' own); ``bias`` as :func:`~jaxlimb.track.filter.run_filter`'s."""
    bm = bias if isinstance(bias, BiasModel) else bias_model(frames, bool(bias))
    nb = len(bm)
    lin = linearise(frames, prop, x0_true, t0, bm, theta)
    Ri = np.linalg.inv(frames.R + lin.A)
    J0 = np.linalg.inv(P0) + np.einsum("kji,kjl,klm->im", lin.G, Ri, lin.G)
    if nb:  # the biases marginalised (Woodbury): G^T (D + W W^T)^-1 G
        W = random_effects(lin.E, frames.t, bm)
        GW = np.einsum("kji,kjl,klm->im", lin.G, Ri, W)
        C = np.eye(W.shape[-1]) + np.einsum("kji,kjl,klm->im", W, Ri, W)
        J0 = J0 - GW @ np.linalg.solve(C, GW.T)
    return np.einsum("kij,jl,kml->kim", lin.Phi, np.linalg.inv(J0), lin.Phi)


__all__ = ["Linearisation", "average_band", "linearise", "measurement_jacobians", "nees", "posterior_crlb"]
