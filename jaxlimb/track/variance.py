r"""How much of ``locate``'s model error the frames of a body share: variance components from the arc.

``locate``'s covariance of a frame is its noise ``N_k`` (the Cramér--Rao bound) plus a model-error term
``M_k = R_k - N_k`` (:mod:`jaxlimb.model_error`).  A sequence does not say, frame by frame, which part of
``M_k`` is the same for every frame of a body (a bias: the bias states of :mod:`jaxlimb.track.bias`) and which
part changes from frame to frame (the limb falling on other pixels); counting all of ``M_k`` as both
double-counts it, and a bias that follows the slowly changing geometry (phase, apparent size) is neither
constant nor independent.  Here the split is estimated from the arc, per body ``b``, with three shares of
``M_k`` that add up to the whole of it, ``alpha_b + beta_b + gamma_b = 1``:

* ``alpha_b``: the independent part: the frame's covariance becomes ``N_k + alpha_b M_k``, that is
  ``(1 - alpha_b) N_k + alpha_b R_k`` (plus the attitude term): positive definite for every ``alpha_b`` in
  ``[0, 1]``.  ``N_k`` must carry the bound's correlations (``covariance_noise``): the centre and the size of
  a partly lit body are strongly correlated, and variances alone leave the likelihood to take that correlation
  from ``M_k``, which then looks larger than the errors are;
* ``beta_b``: the constant common part, the bias states' prior variance ``beta_b sigma_j^2`` (``sigma_j`` the
  :func:`~jaxlimb.track.bias.bias_model` prior, sized by the whole of ``M_k``);
* ``gamma_b``: the slowly varying common part, a random walk of the bias states that adds ``gamma_b sigma_j^2``
  over the arc (power spectral density ``gamma_b sigma_j^2 / T``, ``T`` the arc's duration).

Why the shares add up to one: a common part that moves a body's image the way a change of trajectory would
leaves no residual, since the likelihood integrates the state out, so the arc cannot size it, only say how much
of ``M_k`` is *not* independent.  The size of the model error is ``locate``'s statement, and the arc divides it.
Sized freely, the common part of the rendered transfer came out far below the Moon's shared offset, and the
filter was overconfident (``docs/track.md``).  A body without bias states keeps ``M_k`` independent (``alpha_b`` 1).

The shares maximise the
restricted (residual) likelihood of the arc linearised about a trajectory (Patterson & Thompson 1971,
*Biometrika* 58(3); Koch, *Parameter Estimation and Hypothesis Testing in Linear Models*, Springer 1999, §3.6,
variance components): with the residuals ``r``, the state's columns ``G = dh/dx0`` (flat prior: it is
estimated), the biases as unit-variance effects with columns ``U`` (constant and walk,
:func:`~jaxlimb.track.bias.random_effects`) and ``D = blockdiag(R_k)``, the mixed-model form (Henderson 1975) is

.. math:: -2\ell_R = \log|D| + \log|C| + r^\top D^{-1} r - c^\top C^{-1} c,\quad
          C = W^\top D^{-1} W + \mathrm{diag}(0, I),\ c = W^\top D^{-1} r,\ W = [G,\ U],

which is ``log|Sigma| + log|G^T Sigma^-1 G| + r^T P r`` of ``Sigma = D + U U^T`` without forming ``Sigma``;
its gradient is autodiff, the bounds L-BFGS-B (:func:`scipy.optimize.minimize`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import minimize

from ..errors import ConvergenceError
from .bias import BiasModel, body_names, walk_columns
from .consistency import linearise
from .dynamics import Propagator
from .measurement import Frames

#: The unit step of the state's columns (km, km/s): keeps ``C`` well scaled (as the batch fit's).
_STATE_SCALE = np.array([1e3] * 3 + [1e-2] * 3)


@dataclass(frozen=True)
class VarianceSplit:
    """The estimated split of each body's model error (module docstring).

    Attributes
    ----------
    bodies : the imaged bodies.
    alpha : (n_bodies,) independent part of the model-error term, in ``[0, 1]``.
    beta : (n_bodies,) constant common part (the bias prior's variance scale).
    gamma : (n_bodies,) the common part's random walk: the variance it adds over the arc.  ``alpha + beta + gamma``
        is 1 for a body with bias states; without them ``alpha`` is 1.
    span : the arc's duration (s) that ``gamma`` is spread over.
    """

    bodies: tuple[str, ...]
    alpha: np.ndarray
    beta: np.ndarray
    gamma: np.ndarray
    span: float

    def apply(self, frames: Frames, bias: BiasModel) -> tuple[Frames, BiasModel]:
        """``frames`` with ``R_k = N_k + alpha M_k``; ``bias`` with its prior variance scaled by ``beta`` and a random
        walk of PSD ``gamma sigma^2 / span``; the states of a body with no common part removed."""
        i = [self.bodies.index(b) for b in body_names(frames)]
        R = frames.R_noise + self.alpha[i][:, None, None] * (frames.R - frames.R_noise)
        owner = [self.bodies.index(n.split(".")[0]) for n in bias.names]
        beta, gamma = self.beta[owner], self.gamma[owner]
        keep = (beta > 0) | (gamma > 0)
        sel = BiasModel(tuple(np.asarray(bias.names, dtype=object)[keep]), (bias.sigma * np.sqrt(beta))[keep],
                        bias.select[..., keep], (gamma * bias.sigma**2 / self.span)[keep])
        return replace(frames, R=R), sel

    def to_json(self) -> dict[str, dict[str, float]]:
        """``{body: {"independent": alpha, "common": beta, "walk": gamma}}``."""
        return {b: {"independent": float(a), "common": float(c), "walk": float(w)}
                for b, a, c, w in zip(self.bodies, self.alpha, self.beta, self.gamma)}


def _objective(p, r, G, Ec, Ew, N, M, A, body_of_frame, body_of_const, body_of_walk):  # noqa: ANN001, ANN202
    """``-2 l_R`` of the module docstring at ``p = (alpha_b, sqrt(beta_b), sqrt(gamma_b))`` (square roots: a smooth
    objective at ``beta = 0``)."""
    m = p.shape[0] // 3
    D = N + p[body_of_frame][:, None, None] * M + A
    L = jnp.linalg.cholesky(D)
    W = jnp.concatenate([G, Ec * p[m + body_of_const][None, None, :], Ew * p[2 * m + body_of_walk][None, None, :]], -1)
    Wr = jax.scipy.linalg.solve_triangular(L, r[..., None], lower=True)[..., 0]
    WW = jax.scipy.linalg.solve_triangular(L, W, lower=True)
    n_x = G.shape[-1]
    C = jnp.einsum("kij,kil->jl", WW, WW).at[n_x:, n_x:].add(jnp.eye(W.shape[-1] - n_x))
    c = jnp.einsum("kij,ki->j", WW, Wr)
    Lc = jnp.linalg.cholesky(C)
    q = jax.scipy.linalg.solve_triangular(Lc, c, lower=True)
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diagonal(L, axis1=1, axis2=2))) + 2.0 * jnp.sum(jnp.log(jnp.diag(Lc)))
    return logdet + jnp.sum(Wr * Wr) - q @ q


def _shares(q):  # noqa: ANN001, ANN202
    """``(alpha, sqrt(beta), sqrt(gamma))`` of each body from ``q = (s, theta)``: ``alpha = 1 - s^2``, the common
    part ``s^2 = beta + gamma`` split by the angle ``theta`` (smooth at every bound)."""
    m = q.shape[0] // 2
    s, th = q[:m], q[m:]
    return jnp.concatenate([1.0 - s * s, s * jnp.cos(th), s * jnp.sin(th)])


def _constrained(q, *args):  # noqa: ANN001, ANN202
    return _objective(_shares(q), *args)


_value_and_grad = jax.jit(jax.value_and_grad(_constrained))


def variance_split(frames: Frames, prop: Propagator, x_ref: np.ndarray, t0: float, bias: BiasModel,
                   used: np.ndarray | None = None) -> VarianceSplit | None:
    """The split of each body's model error (module docstring), linearised about the state ``x_ref`` at ``t0``
    (a smoothed or batch estimate) over the frames ``used`` (default all); ``None`` without ``locate``'s
    noise/model split, or when the used frames' measurements do not outnumber the state's six components (the
    restricted likelihood, which integrates the state out, has no residual to split: a filter whose gate refused
    nearly every frame, as with a camera far from the one the frames were measured with).  A body none of whose
    frames is used (the gate refused them all) keeps ``locate``'s whole covariance (``alpha`` 1) and no common
    part."""
    used = np.ones(len(frames), bool) if used is None else np.asarray(used, bool)
    if frames.R_noise is None or frames.z[used].size <= _STATE_SCALE.size:
        return None
    f = frames.subset(used)
    lin = linearise(f, prop, x_ref, t0, replace(bias, select=bias.select[used]))
    span = float(f.t[-1] - f.t[0])
    names = body_names(f)
    # a body whose every frame the gate refused has nothing to split: locate's whole covariance, no common part
    bodies = tuple(dict.fromkeys(names + body_names(frames) + [n.split(".")[0] for n in bias.names]))
    seen = np.isin(np.array(bodies), np.array(names))
    owner = np.array([bodies.index(n.split(".")[0]) for n in bias.names], int)
    Ew, walk_owner = walk_columns(lin.E, f.t)
    args = (lin.r, lin.G * _STATE_SCALE, lin.E * bias.sigma, Ew * (bias.sigma[walk_owner] / np.sqrt(span)),
            f.R_noise, f.R - f.R_noise, lin.A, np.array([bodies.index(b) for b in names]), owner, owner[walk_owner])
    args = tuple(jnp.asarray(a) for a in args)
    m = len(bodies)

    def fg(p: np.ndarray) -> tuple[float, np.ndarray]:
        v, g = _value_and_grad(jnp.asarray(p), *args)
        return float(v), np.asarray(g, float)

    common = [(0.0, 1.0) if b and s else (0.0, 0.0) for b, s in zip(np.isin(np.arange(m), owner), seen)]
    start = np.array([0.7 if hi else 0.0 for _, hi in common] + [0.7] * m)
    sol = minimize(fg, start, jac=True, method="L-BFGS-B", bounds=common + [(0.0, 0.5 * np.pi)] * m)
    if not np.isfinite(sol.fun):
        raise ConvergenceError(f"the split of the bodies' model error did not converge ({sol.message})")
    p = np.asarray(_shares(jnp.asarray(sol.x)))
    return VarianceSplit(bodies, p[:m], p[m : 2 * m] ** 2, p[2 * m :] ** 2, span)


__all__ = ["VarianceSplit", "variance_split"]
