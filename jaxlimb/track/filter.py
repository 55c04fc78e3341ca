r"""Sequential estimation: an extended Kalman filter with NIS gating and a Rauch--Tung--Striebel smoother.

Filter (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*, Wiley 2001,
§5.2 and §10.3).  State ``x = (r, v)`` (km, km/s, geocentric ICRF).  Between frames ``x`` and its state
transition matrix ``Phi`` come from :class:`~jaxlimb.track.dynamics.Propagator` (autodiff through the
integrator); process noise is a continuous white acceleration of power spectral density ``q`` (km^2/s^3)::

    P- = Phi P+ Phi^T + q [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]]

Update with the frame's measurement ``z`` (:mod:`jaxlimb.track.measurement`), ``H = dh/dx`` by
:func:`jax.jacfwd`, innovation ``nu = z - h(x-)``, ``S = H P- H^T + R`` (``R`` with the attitude term), the
normalised innovation squared ``NIS = nu^T S^-1 nu`` and the Joseph-form update.  ``iterations > 1`` re-linearises
the update about the updated state (the iterated EKF, Bell & Cathey 1993).

Gating.  A frame whose NIS exceeds ``chi2.ppf(gate_probability, 3)`` (:func:`scipy.stats.chi2.ppf`: 16.27 at
the default 0.999, the value a correct measurement exceeds once in a thousand frames) is not used: an outlier
(a limb fitted to the wrong edge, a wrong body) would otherwise pull the trajectory.  Its NIS is still reported.

Smoother (Rauch, Tung & Striebel 1965, AIAA J. 3(8)): backward over the frames with
``G_k = P+_k Phi_{k+1}^T (P-_{k+1})^-1``.

Bias states.  With a :class:`~jaxlimb.track.bias.BiasModel` the state is ``(r, v, b)``: the biases of the
bodies' images (:mod:`jaxlimb.track.bias`), with ``Phi`` the identity on ``b``, process noise ``walk dt`` (none
for constant biases), the prior ``N(0, diag(sigma^2))`` and ``h`` the biased image; the results report ``(r, v)``
(its marginal) and the smoothed ``b`` at the first frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from scipy.stats import chi2

from ..errors import ConfigError
from .bias import BiasModel, bias_model
from .dynamics import Propagator
from .measurement import Frames, predict, total_covariance


def gate_threshold(probability: float, dof: int = 3) -> float:
    """NIS gate: the ``probability`` quantile of ``chi2(dof)`` (module docstring)."""
    if not 0.0 < probability < 1.0:
        raise ConfigError(f"the gate probability must be in (0, 1), got {probability!r}")
    return float(chi2.ppf(probability, dof))


def process_noise(q: jax.Array, dt: jax.Array) -> jax.Array:
    """Discrete process noise of a continuous white acceleration of PSD ``q`` over ``dt`` (module docstring)."""
    dt = jnp.abs(dt)
    eye = jnp.eye(3)
    return q * jnp.block([[dt**3 / 3 * eye, dt**2 / 2 * eye], [dt**2 / 2 * eye, dt * eye]])


@dataclass(frozen=True)
class FilterResult:
    """Filtered and smoothed states of a sequence (one row per frame).

    Attributes
    ----------
    t : frame times (s after the arc's reference epoch).
    x_filt, P_filt : filtered state and covariance after each frame.
    x_pred, P_pred : predicted state and covariance at each frame (before its update).
    x_smooth, P_smooth : RTS-smoothed state and covariance.
    innovation, S : innovation ``z - h(x-)`` and its covariance.
    nis : normalised innovation squared of each frame.
    used : whether the frame passed the gate.
    gate : the NIS threshold used.
    bias : the bias states (:mod:`jaxlimb.track.bias`); b_smooth, b_smooth_cov : their smoothed estimate and
        covariance (constant: one for the arc).
    """

    t: np.ndarray
    x_filt: np.ndarray
    P_filt: np.ndarray
    x_pred: np.ndarray
    P_pred: np.ndarray
    x_smooth: np.ndarray
    P_smooth: np.ndarray
    innovation: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    used: np.ndarray
    gate: float
    bias: BiasModel | None = None
    b_smooth: np.ndarray | None = None
    b_smooth_cov: np.ndarray | None = None


def measurement_function(theta, args, sun, E):  # noqa: ANN001, ANN201
    """``h(x)`` of one frame for the state ``x = (r, v, b)`` (``E`` (2, n_b) picks the frame's biases; with no
    bias state, the plain model)."""
    if E.shape[-1] == 0:
        return lambda x: predict(x[:3], theta, *args)
    return lambda x: predict(x[:3], theta, *args, sun, E @ x[6:])


def _update(xp, Pp, z, R, att, theta, args, sun, E, iterations):  # noqa: ANN001, ANN202
    h = measurement_function(theta, args, sun, E)

    x = xp
    for _ in range(iterations):  # iterated EKF: relinearise about the latest estimate
        H = jax.jacfwd(h)(x)
        Rt = total_covariance(x[:3], theta, R, att, *args)
        S = H @ Pp @ H.T + Rt
        K = jnp.linalg.solve(S, H @ Pp).T
        x_new = xp + K @ (z - h(x) - H @ (xp - x))
        if iterations > 1:
            x = x_new
    nu = z - h(xp)
    H0 = jax.jacfwd(h)(xp)
    S0 = H0 @ Pp @ H0.T + total_covariance(xp[:3], theta, R, att, *args)
    return x_new, H, Rt, K, nu, S0


def _augmented_step(prop, x, tp, t, q, qb):  # noqa: ANN001, ANN202
    """Propagate ``(r, v, b)``: the dynamics for ``(r, v)``, ``b`` a random walk of PSD ``qb`` (module docstring)."""
    nb = x.shape[0] - 6
    xp6, Phi6 = prop.step_with_stm(x[:6], tp, t)
    Phi = jnp.eye(6 + nb).at[:6, :6].set(Phi6)
    Q = jnp.zeros((6 + nb, 6 + nb)).at[:6, :6].set(process_noise(q, t - tp)).at[6:, 6:].set(jnp.diag(qb * jnp.abs(t - tp)))
    return jnp.concatenate([xp6, x[6:]]), Phi, Q


@jax.jit(static_argnames=("iterations",))
def _forward(prop, x0, P0, t0, q, qb, gate, t, z, R, att, theta, sun, E, C, body_pos, radius, is_range, f_nom, iterations=1):  # noqa: ANN001, ANN202
    def body(carry, k):  # noqa: ANN001, ANN202
        x, P, tp = carry
        xp, Phi, Q = _augmented_step(prop, x, tp, t[k], q, qb)
        Pp = Phi @ P @ Phi.T + Q
        args = (C[k], body_pos[k], radius[k], is_range[k], f_nom[k])
        xu, H, Rt, K, nu, S = _update(xp, Pp, z[k], R[k], att[k], theta[k], args, sun[k], E[k], iterations)
        nis = nu @ jnp.linalg.solve(S, nu)
        ok = nis <= gate
        IKH = jnp.eye(x.shape[0]) - K @ H
        Pu = IKH @ Pp @ IKH.T + K @ Rt @ K.T
        x_new = jnp.where(ok, xu, xp)
        P_new = jnp.where(ok, 0.5 * (Pu + Pu.T), Pp)
        return (x_new, P_new, t[k]), (xp, Pp, x_new, P_new, Phi, nu, S, nis, ok)

    _, out = jax.lax.scan(body, (x0, P0, t0), jnp.arange(t.shape[0]))
    return out


@jax.jit
def _smooth(xf, Pf, xp, Pp, Phi):  # noqa: ANN001, ANN202
    def body(carry, k):  # noqa: ANN001, ANN202
        xs_next, Ps_next = carry
        G = jnp.linalg.solve(Pp[k + 1], Phi[k + 1] @ Pf[k]).T
        xs = xf[k] + G @ (xs_next - xp[k + 1])
        Ps = Pf[k] + G @ (Ps_next - Pp[k + 1]) @ G.T
        Ps = 0.5 * (Ps + Ps.T)
        return (xs, Ps), (xs, Ps)

    n = xf.shape[0]
    _, (xs, Ps) = jax.lax.scan(body, (xf[-1], Pf[-1]), jnp.arange(n - 2, -1, -1))
    xs = jnp.concatenate([xs[::-1], xf[-1:]], 0)
    Ps = jnp.concatenate([Ps[::-1], Pf[-1:]], 0)
    return xs, Ps


def run_filter(frames: Frames, prop: Propagator, x0, P0, t0: float, *, q: float = 1e-15,
               gate_probability: float = 0.999, iterations: int = 3, bias: bool | BiasModel = True) -> FilterResult:
    """Extended Kalman filter over ``frames`` from the prior ``(x0, P0)`` at ``t0``, then the RTS smoother
    (module docstring).

    Parameters
    ----------
    frames
        The sequence (sorted by time, every ``t >= t0``).
    prop
        The dynamics.
    x0, P0, t0
        Prior state (km, km/s), its 6x6 covariance and its time (s).
    q
        Process-noise PSD (km^2/s^3, >= 0).
    gate_probability
        The NIS gate's chi-square quantile (module docstring).
    iterations
        Update relinearisations (1: the EKF; default 3, the iterated EKF: the first frames after a loose prior
        are far from linear).
    bias
        Estimate the bodies' bias states (:func:`~jaxlimb.track.bias.bias_model` of ``frames``; a
        :class:`~jaxlimb.track.bias.BiasModel` to give them; ``False``: none).
    """
    if len(frames) < 2:
        raise ConfigError(f"a track needs at least 2 frames, got {len(frames)}")
    if np.any(np.diff(frames.t) < 0) or frames.t[0] < t0:
        raise ConfigError("frames must be sorted in time and not before the prior's epoch")
    if not (np.isfinite(q) and q >= 0):
        raise ConfigError(f"the process-noise PSD must be finite and >= 0, got {q!r}")
    gate = gate_threshold(gate_probability)
    f = frames
    bm = bias if isinstance(bias, BiasModel) else bias_model(f, bool(bias))
    nb = len(bm)
    xa = np.concatenate([np.asarray(x0, float), np.zeros(nb)])
    Pa = np.zeros((6 + nb, 6 + nb))
    Pa[:6, :6] = P0
    Pa[6:, 6:] = np.diag(bm.sigma**2)
    sun = f.sun_pos if f.sun_pos is not None else np.zeros((len(f), 3))
    qb = jnp.asarray(bm.walk if bm.walk is not None else np.zeros(nb))
    out = _forward(prop, jnp.asarray(xa), jnp.asarray(Pa), jnp.asarray(float(t0)), q, qb, gate,
                   *map(jnp.asarray, (f.t, f.z, f.R, f.attitude_sigma, f.theta, sun, bm.select)), *f.arrays(),
                   iterations=iterations)
    xp, Pp, xf, Pf, Phi, nu, S, nis, ok = (np.asarray(a) for a in out)
    xs, Ps = (np.asarray(a) for a in _smooth(*map(jnp.asarray, (xf, Pf, xp, Pp, Phi))))
    r6 = slice(0, 6)
    return FilterResult(f.t, xf[:, r6], Pf[:, r6, r6], xp[:, r6], Pp[:, r6, r6], xs[:, r6], Ps[:, r6, r6], nu, S, nis,
                        ok.astype(bool), gate, bm if nb else None, xs[0, 6:] if nb else None,
                        Ps[0, 6:, 6:] if nb else None)


__all__ = ["FilterResult", "gate_threshold", "measurement_function", "process_noise", "run_filter"]
