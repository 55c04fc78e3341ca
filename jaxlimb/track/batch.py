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

Bias states (:mod:`jaxlimb.track.bias`).  The bodies' constant image biases ``b`` are unknowns of the same
least squares, with their prior as whitened residuals ``b_i / sigma_i``; the state's covariance is then the
marginal over them, and the camera's observability is the information on ``theta`` with the state and the
biases unknown.  A walking bias (:mod:`jaxlimb.track.variance`) has its constant part among the unknowns and
its walk marginalised: the frames' residuals, whitened frame by frame, are correlated by the walk's whitened
columns ``U`` (:func:`~jaxlimb.track.bias.walk_effects`), ``cov = I + U U^T``; with the thin SVD
``U = Q S V^T`` the whitening of that covariance is ``I - Q diag(1 - (1 + s^2)^-1/2) Q^T`` (generalised least
squares; recomputed with the frame whiteners at each pass), so the estimate and its covariance are those of the
model the filter uses.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..errors import ConfigError, ConvergenceError
from .bias import BiasModel, bias_model, walk_effects
from .consistency import measurement_jacobians
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
    bias : the bias states' ``{name: {"value", "sigma", "prior_sigma"}}`` (empty without them).
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
    bias: dict = field(default_factory=dict)

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
    prop, t0, ts, z, W, Q, c, weights, x_ref, Dx, theta0, basis, frame_args, prior_x, prior_L, b_ref, b_sig, sun, E = args
    x0 = x_ref + Dx * p[:6]
    theta = jnp.broadcast_to(theta0 + basis @ p[6:10], (ts.shape[0], 4))
    b = b_ref + b_sig * p[10:]
    X = prop.trajectory(x0, t0, ts)
    h = _predict_all(X, theta, frame_args, sun, E, b)
    r = (jnp.einsum("kij,kj->ki", W, z - h) * weights[:, None]).reshape(-1)
    r = r - Q @ (c * (Q.T @ r))  # the walk's correlation (module docstring); Q empty without a walk
    return jnp.concatenate([r, prior_L @ (x0 - prior_x), b / b_sig])


def _predict_all(X, theta, frame_args, sun, E, b):  # noqa: ANN001, ANN202
    """``h`` of every frame (with the frames' biases ``E_k b`` when there are bias states)."""
    if E.shape[-1] == 0:
        return jax.vmap(predict)(X[:, :3], theta, *frame_args)
    return jax.vmap(predict)(X[:, :3], theta, *frame_args, sun, jnp.einsum("kij,j->ki", E, b))


_jacobian = jax.jit(jax.jacfwd(_residuals))


def _solve(args, m: int, max_steps: int):  # noqa: ANN001, ANN202
    sol = optx.least_squares(_residuals, optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8), jnp.zeros(m), args,
                             max_steps=max_steps, throw=False)
    if sol.result != optx.RESULTS.successful:
        raise ConvergenceError(f"the batch fit of the arc did not converge ({sol.result})")
    return np.asarray(sol.value), int(sol.stats["num_steps"])


def observability(F: np.ndarray, names: tuple[str, ...], unobservable_sigma: float = 0.1, n_nuisance: int = 6) -> Observability:
    """Eigen-analysis of the camera block of the Fisher information ``F`` over ``(nuisance, theta)`` (the
    nuisance: ``x0`` (6) and the bias states), ``theta`` in units of its a-priori scales (module docstring)."""
    m = n_nuisance
    Fxx, Fxt, Ftt = F[:m, :m], F[:m, m:], F[m:, m:]
    Fc = Ftt - Fxt.T @ np.linalg.solve(Fxx, Fxt)
    lam, V = np.linalg.eigh(0.5 * (Fc + Fc.T))
    sig = 1.0 / np.sqrt(np.maximum(lam, 1e-300))
    return Observability(tuple(names), lam, V, sig, sig <= unobservable_sigma)


def camera_scales(theta: np.ndarray) -> np.ndarray:
    """The a-priori scale of each camera parameter at ``theta`` (:data:`CAMERA_SCALES`)."""
    return np.array([CAMERA_SCALES[n] * (theta[0] if n == "focal_px" else 1.0) for n in CAMERA_PARAMS])


class _Problem:
    """The pieces of the arc's cost that stay fixed during one optimiser run."""

    def __init__(self, prop, frames, t0, weights, prior, bias: BiasModel) -> None:  # noqa: ANN001
        self.prop, self.frames, self.t0, self.weights, self.prior = prop, frames, float(t0), weights, prior
        self.Dx = np.array([1e3] * 3 + [1e-2] * 3)  # km, km/s: the solver's unit step
        self.bias, self.b_ref = bias, np.zeros(len(bias))
        self.walk: BiasModel | None = None
        self.Q, self.c = np.zeros((3 * len(frames), 0)), np.zeros(0)
        self.m = 10 + len(bias)

    def args(self, x_ref, theta, basis, W):  # noqa: ANN001, ANN201
        f = self.frames
        px, pL = self.prior if self.prior is not None else (jnp.zeros(6), jnp.zeros((6, 6)))
        sun = f.sun_pos if f.sun_pos is not None else np.zeros((len(f), 3))
        return (self.prop, jnp.asarray(self.t0), jnp.asarray(f.t), jnp.asarray(f.z), jnp.asarray(W),
                jnp.asarray(self.Q), jnp.asarray(self.c), jnp.asarray(self.weights), jnp.asarray(x_ref),
                jnp.asarray(self.Dx), jnp.asarray(theta),
                jnp.asarray(basis), f.arrays(), px, pL, jnp.asarray(self.b_ref), jnp.asarray(self.bias.sigma),
                jnp.asarray(sun), jnp.asarray(self.bias.select))

    def whiteners(self, x_ref, theta) -> np.ndarray:  # noqa: ANN001
        """Each frame's ``L_k^-1`` at ``x_ref`` and, with a walk, the low-rank whitening of its correlation
        (``Q``, ``c``: module docstring) over the frames in use."""
        X = np.asarray(self.prop.trajectory(jnp.asarray(x_ref), jnp.asarray(self.t0), jnp.asarray(self.frames.t)))
        W = _whiteners(self.frames, X, np.broadcast_to(theta, self.frames.theta.shape))
        if self.walk is not None:
            Q, s, _ = np.linalg.svd(_walk_rows(self, X, theta, W), full_matrices=False)
            self.Q, self.c = Q, 1.0 - 1.0 / np.sqrt(1.0 + s**2)
        return W

    def fit(self, x_ref, theta, basis, W, max_steps):  # noqa: ANN001, ANN201
        p, n = _solve(self.args(x_ref, theta, basis, W), self.m, max_steps)
        self.b_ref = self.b_ref + self.bias.sigma * p[10:]
        return x_ref + self.Dx * p[:6], theta + basis @ p[6:10], n

    def jacobian(self, x_ref, theta, basis, W) -> np.ndarray:  # noqa: ANN001
        return np.asarray(_jacobian(jnp.zeros(self.m), self.args(x_ref, theta, basis, W)))

    def chi2(self, x0, theta, W) -> np.ndarray:  # noqa: ANN001
        """Each frame's whitened squared residual at ``(x0, theta)`` and the current biases."""
        f = self.frames
        X = self.prop.trajectory(jnp.asarray(x0), jnp.asarray(self.t0), jnp.asarray(f.t))
        th = jnp.broadcast_to(jnp.asarray(theta), f.theta.shape)
        a = self.args(x0, theta, np.zeros((4, 4)), W)
        h = _predict_all(X, th, f.arrays(), a[-2], a[-1], a[-4])
        r = np.einsum("kij,kj->ki", W, f.z - np.asarray(h))
        return np.sum(r * r, axis=1)


def fit_arc(frames: Frames, prop: Propagator, t0: float, x_guess, *, prior=None, calibrate: bool = False,
            gate_probability: float = 0.999, max_passes: int = 3, max_steps: int = 200,
            unobservable_sigma: float = 0.1, max_outlier_fraction: float = 0.2, use: np.ndarray | None = None,
            bias: bool | BiasModel = True) -> ArcFit:
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
    bias
        Estimate the bodies' bias states (module docstring; as :func:`~jaxlimb.track.filter.run_filter`'s).

    Raises
    ------
    ConvergenceError
        The optimiser did not converge.
    """
    theta = np.asarray(frames.theta, float)  # (n, 4) always: one compiled problem for every kind of fit
    if calibrate and not np.all(frames.theta == theta[0]):
        raise ConfigError("self-calibration needs every frame to share one camera")
    gate = gate_threshold(gate_probability)
    prob, bm = _arc_problem(frames, prop, t0, prior, use, bias)
    # the camera moves along the columns of ``basis`` (4x4, zero columns: fixed directions); the problem
    # always has 10 unknowns, so that the state-only and the calibrated fits share one compiled program
    x_ref, basis, obs = np.asarray(x_guess, float), np.zeros((4, 4)), None
    for passes in range(1, max_passes + 1):
        W = prob.whiteners(x_ref, theta)
        x_ref, theta, n_steps = prob.fit(x_ref, theta, basis, W, max_steps)
        for _ in range(3 if calibrate else 0):  # the observable subspace at the solution, refit within it
            S = np.diag(camera_scales(theta[0]))
            J = prob.jacobian(x_ref, theta, S, W)
            J = np.concatenate([J[:, :6], J[:, 10:], J[:, 6:10]], 1)  # (x0, b) the nuisance, then theta
            obs = observability(J.T @ J, CAMERA_PARAMS, unobservable_sigma, 6 + len(bm))
            new = S @ np.where(obs.observable[None, :], obs.eigenvectors, 0.0)
            if np.allclose(new, basis, atol=1e-6 * np.max(np.abs(S))):
                break
            basis = new
            x_ref, theta, n_steps = prob.fit(x_ref, theta, basis, W, max_steps)
        chi = prob.chi2(x_ref, theta, W)
        bad = (chi > gate) & (prob.weights > 0)
        if not np.any(bad) or passes == max_passes or bad.sum() > max_outlier_fraction * np.sum(prob.weights > 0):
            break  # nothing to remove, or so much that the model (a camera, a prior), not the frames, is wrong
        prob.weights = np.where(bad, 0.0, prob.weights)
    return _finish(prob, x_ref, theta, basis, W, obs, n_steps, passes, chi)


def _arc_problem(frames: Frames, prop: Propagator, t0: float, prior, use: np.ndarray | None,  # noqa: ANN001
                 bias: bool | BiasModel) -> tuple[_Problem, BiasModel]:
    """The :class:`_Problem` of :func:`fit_arc` (whitened prior, frame weights, constant bias) and its bias model."""
    pri = None if prior is None else (jnp.asarray(prior[0], float), jnp.asarray(np.linalg.inv(np.linalg.cholesky(prior[1]))))
    bm = bias if isinstance(bias, BiasModel) else bias_model(frames, bool(bias))
    prob = _Problem(prop, frames, t0, np.ones(len(frames)) if use is None else np.asarray(use, float), pri,
                    bm.constant_part())
    prob.walk = bm if bm.walk is not None and np.any(bm.walk > 0) else None
    return prob, bm


def _walk_rows(prob, X, theta, W) -> np.ndarray:  # noqa: ANN001
    """The bias walk's unit-variance columns in the fit's whitened frame rows at the states ``X`` (zero for a
    removed frame)."""
    f = prob.frames
    E = measurement_jacobians(f, X, prob.walk, np.asarray(theta).reshape(-1, 4)[0])[1][:, :, 6:]
    U = np.einsum("kij,kjm->kim", W, walk_effects(E, f.t, prob.walk)) * prob.weights[:, None, None]
    return U.reshape(3 * len(f), -1)


def _finish(prob, x0, theta, basis, W, obs, n_steps, passes, chi) -> ArcFit:  # noqa: ANN001
    nb = len(prob.bias)
    live = np.concatenate([np.ones(6, bool), np.any(basis != 0, axis=0), np.ones(nb, bool)])  # the unknowns that move
    J = prob.jacobian(x0, theta, basis, W)[:, live]
    m = prob.m
    T = np.zeros((m, m))
    T[:6, :6] = np.diag(prob.Dx)
    T[6:10, 6:10] = basis
    T[10:, 10:] = np.diag(prob.bias.sigma)
    T = T[:, live]
    cov = T @ np.linalg.inv(J.T @ J) @ T.T
    used = prob.weights > 0
    res = np.asarray(_residuals(jnp.zeros(m), prob.args(x0, theta, basis, W)))[: 3 * len(prob.frames)].reshape(-1, 3)[used]
    th = np.asarray(theta).reshape(-1, 4)[0]
    camera = None
    if obs is not None:
        ok = obs.parameter_observable()
        camera = {n: ({"value": float(th[i]), "sigma": float(np.sqrt(cov[6 + i, 6 + i]))} if ok[n] else None)
                  for i, n in enumerate(CAMERA_PARAMS)}
    return ArcFit(prob.t0, np.asarray(x0), cov[:6, :6], th, cov[6:10, 6:10], camera, obs, used,
                  float(np.sqrt(np.mean(res * res))) if res.size else float("nan"), n_steps, passes, chi,
                  prob.bias.to_json(prob.b_ref, cov[10:, 10:]) if nb else {})


__all__ = ["CAMERA_SCALES", "ArcFit", "Observability", "camera_scales", "fit_arc", "observability"]
