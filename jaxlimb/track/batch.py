r"""Batch least squares of a whole arc, and self-calibration of the camera from the limbs.

The arc's unknowns are the state at the reference time ``x0`` and, optionally, the camera parameters
``theta = (f, r_c, c_c, k1)`` (:mod:`jaxlimb.track.measurement`).  The cost is the sum of the whitened
residuals of every frame::

    J(x0, theta) = sum_k | L_k^-1 (z_k - h(x(t_k; x0), theta)) |^2 + | L_0^-1 (x0 - x_prior) |^2

(``L_k L_k^T`` the frame's covariance with its attitude term, the last term only with a prior), minimised by
optimistix's Levenberg--Marquardt; ``x(t_k; x0)`` is one diffrax solve over the arc
(:meth:`~jaxlimb.track.dynamics.Propagator.trajectory`) and the Jacobian of the residuals is forward-mode
autodiff through the integrator, the camera model and the attitude: pixels <- camera <- state.  The
covariance is ``(J^T J)^-1`` at the solution (Gauss--Newton; Tapley, Schutz & Born, *Statistical Orbit
Determination*, Elsevier 2004, §4.3).

Outlier frames.  After a fit, a frame whose ``r_k^T r_k`` exceeds the NIS gate (:func:`~jaxlimb.track.filter.
gate_threshold`) is removed and the fit repeated (at most ``max_passes`` times).

Observability of the camera (self-calibration).  With ``F = J^T J`` over ``(x0, theta)``, the information on
``theta`` with the state unknown is the Schur complement ``F_tt - F_tx F_xx^-1 F_xt``.  Scaled by the
a-priori scale ``s`` of each parameter (:data:`CAMERA_SCALES`: 1 % of ``f``, 10 px, 1e-2), its eigenvalues
``lambda_i`` and eigenvectors ``v_i`` say which combinations the sequence determines: a direction with
``1/sqrt(lambda_i) > unobservable_sigma`` (default 0.1: the data would pin it no better than a tenth of its
scale) is *unobservable*; it is returned as a direction, and the fit moves the camera only within the
observable subspace (``theta = theta_0 + S V_obs beta``).  A parameter is reported with a number and a sigma
only when its own axis lies in the observable subspace (projection on the unobservable one below 0.1);
otherwise it is ``None`` and named in ``unobservable``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..errors import ConfigError, ConvergenceError
from .dynamics import Propagator
from .filter import gate_threshold
from .measurement import CAMERA_PARAMS, Frames, predict, total_covariance

#: A-priori scale of each camera parameter (module docstring): f (fraction of f), r_c, c_c (px), k1.
CAMERA_SCALES = {"focal_px": 0.01, "principal_r": 10.0, "principal_c": 10.0, "k1": 0.01}


@dataclass(frozen=True)
class Observability:
    """Eigen-analysis of the camera's information (module docstring).

    Attributes
    ----------
    names : the camera parameters analysed.
    eigenvalues : of the scaled information, ascending.
    eigenvectors : columns, in scaled parameter space (unit vectors over ``names``).
    sigma_scaled : ``1/sqrt(eigenvalue)`` (units of the a-priori scales).
    observable : per eigen-direction.
    """

    names: tuple[str, ...]
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    sigma_scaled: np.ndarray
    observable: np.ndarray

    def unobservable_directions(self) -> list[dict[str, float]]:
        """Each unobservable direction as ``{parameter: component}`` (scaled units)."""
        return [{n: float(v) for n, v in zip(self.names, self.eigenvectors[:, i])}
                for i in range(len(self.names)) if not self.observable[i]]

    def parameter_observable(self, tol: float = 0.1) -> dict[str, bool]:
        """Whether each parameter's own axis lies in the observable subspace (module docstring)."""
        U = self.eigenvectors[:, ~self.observable]
        return {n: bool(np.linalg.norm(U[i]) < tol) for i, n in enumerate(self.names)}

    def to_json(self) -> dict:
        return {"parameters": list(self.names), "eigenvalues": self.eigenvalues.tolist(),
                "sigma_scaled": self.sigma_scaled.tolist(), "eigenvectors": self.eigenvectors.T.tolist(),
                "observable": self.observable.tolist(), "unobservable_directions": self.unobservable_directions()}


@dataclass(frozen=True)
class ArcFit:
    """The batch solution of an arc.

    Attributes
    ----------
    t0, x0, P0 : reference time, state and its covariance (6x6).
    theta, theta_cov : the camera (``CAMERA_PARAMS``) and its 4x4 covariance (zero where not estimated).
    camera : per parameter ``{"value", "sigma"}``, or ``None`` for an unobservable one (self-calibration).
    observability : the eigen-analysis (self-calibration) or ``None``.
    used : frames kept (after outlier removal); residual_rms : of the whitened residuals of the kept frames.
    n_steps : optimiser steps of the last pass; passes : fits run.
    """

    t0: float
    x0: np.ndarray
    P0: np.ndarray
    theta: np.ndarray
    theta_cov: np.ndarray
    camera: dict | None
    observability: Observability | None
    used: np.ndarray
    residual_rms: float
    n_steps: int
    passes: int
    chi2: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def states(self, prop: Propagator, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States and covariances at ``ts`` (mapped by the state transition matrices; camera uncertainty not
        included)."""
        x0 = jnp.asarray(self.x0)

        def traj(x):  # noqa: ANN001, ANN202
            return prop.trajectory(x, jnp.asarray(self.t0), jnp.asarray(ts))

        X = np.asarray(traj(x0))
        Phi = np.asarray(jax.jacfwd(traj)(x0))
        return X, np.einsum("kij,jl,kml->kim", Phi, self.P0, Phi)


def _whiteners(frames: Frames, X: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``L_k^-1`` of each frame's covariance with its attitude term at the states ``X``."""
    Rt = jax.vmap(total_covariance)(jnp.asarray(X[:, :3]), jnp.asarray(theta), *map(jnp.asarray, (frames.R, frames.attitude_sigma)),
                                    *frames.arrays())
    return np.linalg.inv(np.linalg.cholesky(np.asarray(Rt)))


def _residuals(p, args):  # noqa: ANN001, ANN202
    """Whitened residuals of every frame (zero weight: removed) and of the prior (module docstring)."""
    prop, t0, ts, z, W, weights, x_ref, Dx, theta0, basis, frame_args, prior_x, prior_L = args
    x0 = x_ref + Dx * p[:6]
    theta = jnp.broadcast_to(theta0 + basis @ p[6:], (ts.shape[0], 4))
    X = prop.trajectory(x0, t0, ts)
    h = jax.vmap(predict)(X[:, :3], theta, *frame_args)
    r = jnp.einsum("kij,kj->ki", W, z - h) * weights[:, None]
    return jnp.concatenate([r.reshape(-1), prior_L @ (x0 - prior_x)])


_jacobian = jax.jit(jax.jacfwd(_residuals))


def _solve(args, m: int, max_steps: int):  # noqa: ANN001, ANN202
    sol = optx.least_squares(_residuals, optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8), jnp.zeros(m), args,
                             max_steps=max_steps, throw=False)
    if sol.result != optx.RESULTS.successful:
        raise ConvergenceError(f"the batch fit of the arc did not converge ({sol.result})")
    return np.asarray(sol.value), int(sol.stats["num_steps"])


def observability(F: np.ndarray, names: tuple[str, ...], unobservable_sigma: float = 0.1) -> Observability:
    """Eigen-analysis of the camera block of the Fisher information ``F`` over ``(x0 (6), theta)``, ``theta``
    in units of its a-priori scales (module docstring)."""
    Fxx, Fxt, Ftt = F[:6, :6], F[:6, 6:], F[6:, 6:]
    Fc = Ftt - Fxt.T @ np.linalg.solve(Fxx, Fxt)
    lam, V = np.linalg.eigh(0.5 * (Fc + Fc.T))
    sig = 1.0 / np.sqrt(np.maximum(lam, 1e-300))
    return Observability(tuple(names), lam, V, sig, sig <= unobservable_sigma)


def camera_scales(theta: np.ndarray) -> np.ndarray:
    """The a-priori scale of each camera parameter at ``theta`` (:data:`CAMERA_SCALES`)."""
    return np.array([CAMERA_SCALES[n] * (theta[0] if n == "focal_px" else 1.0) for n in CAMERA_PARAMS])


class _Problem:
    """The pieces of the arc's cost that stay fixed during one optimiser run."""

    def __init__(self, prop, frames, t0, weights, prior) -> None:  # noqa: ANN001
        self.prop, self.frames, self.t0, self.weights, self.prior = prop, frames, float(t0), weights, prior
        self.Dx = np.array([1e3] * 3 + [1e-2] * 3)  # km, km/s: the solver's unit step

    def args(self, x_ref, theta, basis, W):  # noqa: ANN001, ANN201
        f = self.frames
        px, pL = self.prior if self.prior is not None else (jnp.zeros(6), jnp.zeros((6, 6)))
        return (self.prop, jnp.asarray(self.t0), jnp.asarray(f.t), jnp.asarray(f.z), jnp.asarray(W),
                jnp.asarray(self.weights), jnp.asarray(x_ref), jnp.asarray(self.Dx), jnp.asarray(theta),
                jnp.asarray(basis), f.arrays(), px, pL)

    def whiteners(self, x_ref, theta) -> np.ndarray:  # noqa: ANN001
        X = np.asarray(self.prop.trajectory(jnp.asarray(x_ref), jnp.asarray(self.t0), jnp.asarray(self.frames.t)))
        return _whiteners(self.frames, X, np.broadcast_to(theta, self.frames.theta.shape))

    def fit(self, x_ref, theta, basis, W, max_steps):  # noqa: ANN001, ANN201
        p, n = _solve(self.args(x_ref, theta, basis, W), 10, max_steps)
        return x_ref + self.Dx * p[:6], theta + basis @ p[6:], n

    def jacobian(self, x_ref, theta, basis, W) -> np.ndarray:  # noqa: ANN001
        return np.asarray(_jacobian(jnp.zeros(10), self.args(x_ref, theta, basis, W)))


def fit_arc(frames: Frames, prop: Propagator, t0: float, x_guess, *, prior=None, calibrate: bool = False,
            gate_probability: float = 0.999, max_passes: int = 3, max_steps: int = 200,
            unobservable_sigma: float = 0.1, max_outlier_fraction: float = 0.2, use: np.ndarray | None = None) -> ArcFit:
    """Batch least squares of the arc, with the camera if ``calibrate`` (module docstring).

    Parameters
    ----------
    frames, prop
        The sequence and the dynamics.
    t0, x_guess
        Reference time (s) of the estimated state and a first guess of it.
    prior
        Optional ``(x_prior, P_prior)`` at ``t0``.
    calibrate
        Estimate the camera too (every frame must share one camera).
    gate_probability, max_passes, max_outlier_fraction
        Outlier removal (module docstring); when more than ``max_outlier_fraction`` of the frames exceed the
        gate none is removed (the model is wrong, not the frames: the residuals say so).
    unobservable_sigma
        Observability threshold (module docstring).
    use
        Frames to fit (boolean mask; default all): a sub-arc keeps the compiled problem of the whole one.

    Raises
    ------
    ConvergenceError
        The optimiser did not converge.
    """
    theta = np.asarray(frames.theta, float)  # (n, 4) always: one compiled problem for every kind of fit
    if calibrate and not np.all(frames.theta == theta[0]):
        raise ConfigError("self-calibration needs every frame to share one camera")
    gate = gate_threshold(gate_probability)
    pri = None if prior is None else (jnp.asarray(prior[0], float), jnp.asarray(np.linalg.inv(np.linalg.cholesky(prior[1]))))
    prob = _Problem(prop, frames, t0, np.ones(len(frames)) if use is None else np.asarray(use, float), pri)
    # the camera moves along the columns of ``basis`` (4x4, zero columns: fixed directions); the problem
    # always has 10 unknowns, so that the state-only and the calibrated fits share one compiled program
    x_ref, basis, obs = np.asarray(x_guess, float), np.zeros((4, 4)), None
    for passes in range(1, max_passes + 1):
        W = prob.whiteners(x_ref, theta)
        x_ref, theta, n_steps = prob.fit(x_ref, theta, basis, W, max_steps)
        for _ in range(3 if calibrate else 0):  # the observable subspace at the solution, refit within it
            S = np.diag(camera_scales(theta[0]))
            J = prob.jacobian(x_ref, theta, S, W)
            obs = observability(J.T @ J, CAMERA_PARAMS, unobservable_sigma)
            new = S @ np.where(obs.observable[None, :], obs.eigenvectors, 0.0)
            if np.allclose(new, basis, atol=1e-6 * np.max(np.abs(S))):
                break
            basis = new
            x_ref, theta, n_steps = prob.fit(x_ref, theta, basis, W, max_steps)
        chi = _frame_chi2(prop, frames, t0, x_ref, theta, W)
        bad = (chi > gate) & (prob.weights > 0)
        if not np.any(bad) or passes == max_passes or bad.sum() > max_outlier_fraction * np.sum(prob.weights > 0):
            break  # nothing to remove, or so much that the model (a camera, a prior), not the frames, is wrong
        prob.weights = np.where(bad, 0.0, prob.weights)
    return _finish(prob, x_ref, theta, basis, W, obs, n_steps, passes, chi)


def _frame_chi2(prop, frames, t0, x0, theta, W):  # noqa: ANN001, ANN202
    X = prop.trajectory(jnp.asarray(x0), jnp.asarray(t0), jnp.asarray(frames.t))
    th = jnp.broadcast_to(jnp.asarray(theta), frames.theta.shape)
    h = jax.vmap(predict)(X[:, :3], th, *frames.arrays())
    r = np.einsum("kij,kj->ki", W, frames.z - np.asarray(h))
    return np.sum(r * r, axis=1)


def _finish(prob, x0, theta, basis, W, obs, n_steps, passes, chi) -> ArcFit:  # noqa: ANN001
    live = np.concatenate([np.ones(6, bool), np.any(basis != 0, axis=0)])  # the unknowns that move
    J = prob.jacobian(x0, theta, basis, W)[:, live]
    T = np.zeros((10, 10))
    T[:6, :6] = np.diag(prob.Dx)
    T[6:, 6:] = basis
    T = T[:, live]
    cov = T @ np.linalg.inv(J.T @ J) @ T.T
    m = 10
    used = prob.weights > 0
    res = np.asarray(_residuals(jnp.zeros(m), prob.args(x0, theta, basis, W)))[: 3 * len(prob.frames)].reshape(-1, 3)[used]
    th = np.asarray(theta).reshape(-1, 4)[0]
    camera = None
    if obs is not None:
        ok = obs.parameter_observable()
        camera = {n: ({"value": float(th[i]), "sigma": float(np.sqrt(cov[6 + i, 6 + i]))} if ok[n] else None)
                  for i, n in enumerate(CAMERA_PARAMS)}
    return ArcFit(prob.t0, np.asarray(x0), cov[:6, :6], th, cov[6:, 6:], camera, obs, used,
                  float(np.sqrt(np.mean(res * res))) if res.size else float("nan"), n_steps, passes, chi)


__all__ = ["CAMERA_SCALES", "ArcFit", "Observability", "camera_scales", "fit_arc", "observability"]
