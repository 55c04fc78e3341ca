r"""The log-posterior of a limb fit: the likelihood of the pixels under a limb model, the noise treatments and the
priors (module docstring of :mod:`jaxlimb.analysis.posterior`).

Weights.  With per-pixel weights ``w`` (the fit's: ``1/sigma_i`` in units of ``sigma``) the residuals are
:math:`w_i (f(\theta, x_i) - z_i)` and ``n`` counts the pixels with ``w > 0``: the likelihood of the fit's own
weighted least squares.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ...errors import LimbInputError
from ...fitting import bucket_size, pad_pixels
from ...models import LimbModel, LimbParams

_POSITIVE = frozenset({"radius", "a", "k", "rho", "sigma", "amp"})


class NoiseModel(enum.Enum):
    """How the noise level enters the likelihood (module docstring)."""

    KNOWN = "known"
    MARGINAL = "marginal"
    FREE = "free"


@dataclass(frozen=True)
class Priors:
    """Independent priors on the model parameters (by name).

    Attributes
    ----------
    gaussian
        ``{name: (mean, sd)}`` Gaussian priors, e.g. ``{"radius": (150.0, 15.0)}``.
    bounds
        ``{name: (low, high)}`` open intervals (use ``math.inf``); ``radius``, ``a``, ``k``
        and ``rho`` are always bounded below by 0.
    """

    gaussian: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, (mu, sd) in self.gaussian.items():
            if not (math.isfinite(mu) and math.isfinite(sd) and sd > 0):
                raise LimbInputError(f"Gaussian prior on `{name}` needs a finite mean and sd > 0, got ({mu!r}, {sd!r})")
        for name, (lo, hi) in self.bounds.items():
            if not lo < hi:
                raise LimbInputError(f"bounds on `{name}` must satisfy low < high, got ({lo!r}, {hi!r})")


def priors_from_hints(hints: Mapping[str, Any], model: LimbModel, default_frac: float = 0.1) -> Priors:
    """Priors a navigation filter supplies through the hints (docs/design.md, HINTS).

    ``expected_radius_px`` with ``expected_radius_uncertainty_frac`` (default
    ``default_frac``) becomes a Gaussian prior on ``radius`` (circle) or ``a`` (ellipse)
    with sd ``frac * expected_radius_px``.  Unknown keys are ignored.

    Parameters
    ----------
    hints : mapping
        The hints, as a dict.
    model : LimbModel
        The model to sample; a model with neither ``radius`` nor ``a`` gets no prior.
    default_frac : float
        Relative sd of the radius prior when the hints give none.

    Returns
    -------
    Priors
        At most one Gaussian prior (mean and sd in px).

    Raises
    ------
    LimbInputError
        A non-positive or non-numeric radius or fraction.
    """
    gauss: dict[str, tuple[float, float]] = {}
    r = hints.get("expected_radius_px")
    if r is not None:
        from ..._validate import POSITIVE, number

        frac = number(hints.get("expected_radius_uncertainty_frac", default_frac),
                      "hints `expected_radius_uncertainty_frac`", POSITIVE, error=LimbInputError)
        r = number(r, "hints `expected_radius_px`", POSITIVE, error=LimbInputError)
        name = "radius" if "radius" in model.param_names else ("a" if "a" in model.param_names else None)
        if name is not None:
            gauss[name] = (r, frac * r)
    return Priors(gaussian=gauss)


@dataclass(frozen=True)
class LogPosterior:
    """A jitted log-posterior over the sampled parameters.

    Attributes
    ----------
    names : sampled parameter names (free model parameters, then ``log_sigma`` for ``FREE``).
    single : ``(d,) -> ()`` jitted, one walker.
    batch : ``(w, d) -> (w,)`` jitted ``vmap`` of ``single``.
    theta0 : full model parameter vector (fixed entries are held at these values).
    free_idx : indices of the free model parameters.
    n_pixels : number of pixels in the likelihood (weight > 0).
    """

    names: tuple[str, ...]
    single: Callable[[Any], Any]
    batch: Callable[[Any], Any]
    theta0: np.ndarray
    free_idx: tuple[int, ...]
    n_pixels: int
    model: LimbModel

    def __call__(self, y: np.ndarray) -> np.ndarray:
        """Evaluate at ``(d,)`` or ``(w, d)`` points (NumPy in, NumPy out)."""
        y = np.asarray(y, dtype=float)
        return np.asarray(self.batch(y) if y.ndim == 2 else self.single(y))

    def params(self, y: np.ndarray) -> LimbParams:
        """Model parameters (a container) at a sampled vector ``y``.

        Parameters
        ----------
        y : np.ndarray (d,)
            A point over :attr:`names` (a ``log_sigma`` entry is ignored).

        Returns
        -------
        LimbParams
            ``theta0`` with the free entries replaced by ``y``.
        """
        th = self.theta0.copy()
        th[list(self.free_idx)] = np.asarray(y)[: len(self.free_idx)]
        return self.model.params_type.from_vector(jnp.asarray(th))


def _checked_inputs(model: LimbModel, coords: Any, z: Any, init: LimbParams, fixed: Sequence[str], noise: NoiseModel,
                    sigma: float | None, priors: Priors, weights: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels, intensities and weights as float arrays, after every check of :func:`log_posterior`."""
    if not isinstance(init, model.params_type):
        raise LimbInputError(f"`init` must be a {model.params_type.__name__}, got {type(init).__name__}")
    names_all = model.param_names
    for nm in (*fixed, *priors.gaussian, *priors.bounds):
        if nm not in names_all:
            raise LimbInputError(f"unknown parameter {nm!r}; the {model.name!r} model has {list(names_all)}")
    coords = np.asarray(coords, dtype=float)
    z = np.asarray(z, dtype=float)
    if z.ndim != 1 or coords.shape[0] != z.shape[0] or z.size == 0:
        raise LimbInputError(f"`coords` {coords.shape} and `z` {z.shape} must hold the same n > 0 pixels")
    w = np.ones_like(z) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != z.shape or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise LimbInputError(f"`weights` must be {z.shape} finite numbers >= 0")
    if not (np.all(np.isfinite(coords)) and np.all(np.isfinite(z))):
        raise LimbInputError("`coords` and `z` must be finite")
    if noise is NoiseModel.KNOWN and not (sigma is not None and np.isfinite(sigma) and sigma > 0):
        raise LimbInputError(f"`sigma` must be > 0 with noise='known', got {sigma!r}")
    return coords, z, w


def _prior_arrays(free_names: Sequence[str], priors: Priors) -> tuple[np.ndarray, ...]:
    """Lower and upper bounds (positivity and ``priors.bounds``), Gaussian means and inverse sds (0 = none)."""
    q = len(free_names)
    lo = np.full(q, -np.inf)
    hi = np.full(q, np.inf)
    mu = np.zeros(q)
    inv_sd = np.zeros(q)  # 0 = no Gaussian prior
    for j, nm in enumerate(free_names):
        if nm in _POSITIVE:
            lo[j] = 0.0
        if nm in priors.bounds:
            lo[j] = max(lo[j], priors.bounds[nm][0])
            hi[j] = priors.bounds[nm][1]
        if nm in priors.gaussian:
            mu[j], sd = priors.gaussian[nm]
            inv_sd[j] = 1.0 / sd
    return lo, hi, mu, inv_sd


def _log_post(model: LimbModel, free_idx: tuple[int, ...], noise: NoiseModel, y: jax.Array, data: tuple) -> jax.Array:
    """One walker's log-posterior (module docstring); ``data = (theta0, coords, z, w, n, inv_var, lo, hi, mu, isd)``."""
    theta0, coords, z, w, n, inv_var, lo, hi, mu, isd = data
    q = len(free_idx)
    yq = y[:q]
    theta = theta0.at[jnp.asarray(free_idx)].set(yq)
    r = w * (model.intensity(model.params_type.from_vector(theta), coords) - z)
    s = jnp.sum(r * r)
    if noise is NoiseModel.KNOWN:
        ll = -0.5 * s * inv_var
    elif noise is NoiseModel.MARGINAL:
        ll = -0.5 * n * jnp.log(s)
    else:
        ls = y[q]
        ll = -0.5 * s * jnp.exp(-2.0 * ls) - n * ls
    out = ll - 0.5 * jnp.sum(((yq - mu) * isd) ** 2)
    inside = jnp.all(yq > lo) & jnp.all(yq < hi)
    return jnp.where(inside & jnp.isfinite(out), out, -jnp.inf)


_single_jit = jax.jit(_log_post, static_argnums=(0, 1, 2))
_batch_jit = jax.jit(jax.vmap(_log_post, in_axes=(None, None, None, 0, None)), static_argnums=(0, 1, 2))


def log_posterior(model: LimbModel, coords: Any, z: Any, init: LimbParams, *, fixed: Sequence[str] = (),
                  noise: NoiseModel | str = NoiseModel.MARGINAL, sigma: float | None = None,
                  priors: Priors | None = None, weights: Any = None) -> LogPosterior:
    """Build the jitted (and vmapped) log-posterior of the module docstring.

    The pixels are padded to their bucket (:func:`jaxlimb.fitting.bucket_size`, zero weight): posteriors of
    pixel sets of similar size share one compiled program.

    Parameters
    ----------
    model : LimbModel
        The limb model (a sigmoid of Mortari et al. 2016 Sec. V, or any model of :mod:`jaxlimb.models`).
    coords : array (n, 2)
        Pixels as (row, col) (``(n,)`` columns for ``LINEAR``).
    z : array (n,)
        Intensities (DN).
    init : LimbParams
        Parameter container; the fixed parameters are held at its values.
    fixed : sequence of str
        Names of the parameters not sampled.
    noise : NoiseModel or {"known", "marginal", "free"}
        Treatment of the noise level (:class:`NoiseModel`).
    sigma : float, optional
        Noise standard deviation (DN), required with ``"known"``.
    priors : Priors, optional
        Default: positivity bounds only.
    weights : array (n,), optional
        Per-pixel weights of the fit (module docstring); default all 1.

    Returns
    -------
    LogPosterior
        Over the free parameters (then ``log_sigma`` with ``"free"``).

    Raises
    ------
    LimbInputError
        Shape mismatch, non-finite data, unknown parameter names.
    """
    noise = NoiseModel(noise) if not isinstance(noise, NoiseModel) else noise
    priors = priors or Priors()
    coords, z, w = _checked_inputs(model, coords, z, init, fixed, noise, sigma, priors, weights)
    free_idx = model.free_indices(fixed)
    free_names = tuple(model.param_names[i] for i in free_idx)
    theta0 = np.asarray(init.to_vector(), dtype=float)
    n = int(np.count_nonzero(w > 0))
    coords, z, w = pad_pixels(coords, z, w, bucket_size(z.size))
    inv_var = 0.0 if sigma is None else 1.0 / float(sigma) ** 2
    data = tuple(jax.device_put(np.asarray(a, float)) for a in (theta0, coords, z, w, n, inv_var,
                                                                 *_prior_arrays(free_names, priors)))
    names = free_names + (("log_sigma",) if noise is NoiseModel.FREE else ())
    return LogPosterior(names, lambda y: _single_jit(model, free_idx, noise, y, data),
                        lambda y: _batch_jit(model, free_idx, noise, y, data), theta0, free_idx, n, model)


__all__ = ["LogPosterior", "NoiseModel", "Priors", "log_posterior", "priors_from_hints"]
