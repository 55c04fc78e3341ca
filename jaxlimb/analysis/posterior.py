r"""Bayesian posterior of a sigmoid limb fit, sampled with emcee.

Model.  The pixel intensities are :math:`z_i = f(\theta, x_i) + \epsilon_i`,
:math:`\epsilon_i \sim N(0, \sigma^2)` i.i.d., with :math:`f` a sigmoid limb model
(Eq. 12, 16 or Sec. V-C of Mortari et al. 2016 [1]_).  The log-posterior of the free
parameters :math:`\theta` is

.. math:: \log p(\theta \mid z) = \log L(\theta) + \log \pi(\theta) + \text{const},
          \qquad S(\theta) = \sum_i (f(\theta, x_i) - z_i)^2,

with three treatments of the noise level (:class:`NoiseModel`):

* ``KNOWN``: :math:`\log L = -S / (2\sigma^2)` (``sigma`` given: e.g. 10 grey levels,
  Aerospace 2015 Sec. 7.2 [2]_);
* ``MARGINAL``: :math:`\sigma` integrated out under the Jeffreys prior
  :math:`\pi(\sigma) \propto 1/\sigma`:
  :math:`\int_0^\infty \sigma^{-n-1} e^{-S/2\sigma^2}\,d\sigma \propto S^{-n/2}`, so
  :math:`\log L = -\tfrac{n}{2}\log S` (a Student-t-like likelihood; for large ``n`` the
  same as plugging in :math:`\hat\sigma^2 = S/n`);
* ``FREE``: :math:`\log\sigma` is sampled as one more parameter (flat prior on
  :math:`\log\sigma`, i.e. Jeffreys), :math:`\log L = -S e^{-2\log\sigma}/2 - n\log\sigma`.

Priors (:class:`Priors`) are independent: box bounds (``k > 0``, ``radius > 0``,
``a > 0``, ``rho > 0`` always) and optional Gaussians, e.g. a radius prior from the
hints' ``expected_radius_px`` +- ``expected_radius_uncertainty_frac``
(:func:`priors_from_hints`).

Sampler.  :func:`sample_posterior` runs emcee's affine-invariant ensemble sampler [3]_
with a *vectorised* log-posterior: one ``jax.jit(jax.vmap(...))`` call evaluates half
the ensemble (``EnsembleSampler(..., vectorize=True)``), instead of one Python call (and
one JAX dispatch) per walker.  Walkers start in a Gaussian ball around the fit, scaled by
its Laplace covariance.  The chain runs in chunks; after each chunk the integrated
autocorrelation time :math:`\tau` is estimated (emcee's ``get_autocorr_time(tol=0)``) and
the run stops once the chain is longer than ``tau_factor`` :math:`\times\max\tau` and
:math:`\tau` changed by less than ``tau_rtol`` since the last chunk (the criterion of
emcee's documentation), or at ``max_steps`` / ``max_time_s`` with ``converged=False``.
Burn-in is ``2 max(tau)`` and thinning ``max(1, min(tau)/2)``.

Comparison.  :func:`compare_uncertainties` puts the posterior standard deviations beside
the Laplace covariance :math:`\hat\sigma^2 (J^\top J)^{-1}` of :func:`jaxlimb.fitting.fit`
and the Cramér--Rao bound (:mod:`jaxlimb.analysis.crlb`).  For a well-posed problem (full
limb, sharp edge) the three agree to a few per cent; they part where the likelihood is
not Gaussian in :math:`\theta` (short arcs, a blurred edge with ``k`` poorly
constrained): ``benchmarks/posterior_study.py`` measures where.

Example
-------
>>> from jaxlimb.analysis.posterior import (PosteriorOptions, log_posterior,  # doctest: +SKIP
...     sample_posterior, synthetic_circle, compare_uncertainties, comparison_table)
>>> s = synthetic_circle(radius=60.0, sigma=10.0, arc_deg=60.0)              # doctest: +SKIP
>>> f = fit(CIRCLE, s.coords, s.z, s.truth)                                 # doctest: +SKIP
>>> lp = log_posterior(CIRCLE, s.coords, s.z, f.params, noise="known", sigma=10.0)  # doctest: +SKIP
>>> post = sample_posterior(lp, f, options=PosteriorOptions(seed=1))        # doctest: +SKIP
>>> print(comparison_table(compare_uncertainties(post, f, crlb(CIRCLE, s.coords, s.truth, 10.0))))  # doctest: +SKIP

Measured (``benchmarks/posterior_study.py``; 2 shared CPU cores): the six-parameter
posterior of a full limb (3015 px) converges (``N > 50 tau``, ``tau ~ 70``) in ~5000 steps
x 32 walkers, 15-20 s; the vectorised log-posterior is ~3x faster than one call per walker.

References
----------
.. [1] D. Mortari, C. N. D'Souza, R. Zanetti, "Image Processing of Illuminated Ellipsoid",
   J. Spacecraft and Rockets 53(3), 2016, doi:10.2514/1.A33342.
.. [2] Aerospace 2015 (vol. 2), Moon image processing: gradient, RANSAC, circular sigmoid
   (``/work/shared/papers/aerospace-2015-moon-gradient-ransac-csf.md``), Sec. 7.
.. [3] D. Foreman-Mackey et al., "emcee: The MCMC Hammer", PASP 125, 306 (2013),
   doi:10.1086/670067; J. Goodman, J. Weare, CAMCoS 5(1), 65 (2010).
"""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import ConvergenceError, LimbInputError, NoBodyError, PosteriorImproperError
from ..fitting import LimbFit
from ..models import LimbModel, LimbParams
from .crlb import CramerRao

_POSITIVE = frozenset({"radius", "a", "k", "rho"})


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
    """
    gauss: dict[str, tuple[float, float]] = {}
    r = hints.get("expected_radius_px")
    if r is not None:
        from .._validate import POSITIVE, number

        frac = number(hints.get("expected_radius_uncertainty_frac", default_frac),
                      "hints `expected_radius_uncertainty_frac`", POSITIVE, error=LimbInputError)
        r = number(r, "hints `expected_radius_px`", POSITIVE, error=LimbInputError)
        name = "radius" if "radius" in model.param_names else ("a" if "a" in model.param_names else None)
        if name is not None:
            gauss[name] = (r, frac * r)
    return Priors(gaussian=gauss)


@dataclass(frozen=True)
class PosteriorOptions:
    """Settings of :func:`sample_posterior`."""

    n_walkers: int = 32
    """Ensemble size (even, >= 2 x the number of sampled parameters)."""
    chunk: int = 100
    """Steps between autocorrelation checks (emcee's documentation checks every 100)."""
    max_steps: int = 20_000
    """Stop (not converged) after this many steps."""
    max_time_s: float = 120.0
    """Stop (not converged) after this much wall time."""
    tau_factor: float = 50.0
    """Converged when the chain is longer than ``tau_factor * max(tau)`` ..."""
    tau_rtol: float = 0.01
    """... and ``tau`` changed by less than this fraction since the previous chunk."""
    init_scale: float = 0.5
    """Initial ball: ``N(fit, init_scale^2 * Laplace covariance)``."""
    vectorize: bool = True
    """Evaluate the ensemble in one vmapped call (False: one call per walker)."""
    seed: int = 0
    """Seed of the initial ball and of emcee's generator."""

    def __post_init__(self) -> None:
        from .._validate import POSITIVE, Range, number

        if number(self.n_walkers, "`n_walkers`", Range(4, 100_000), integer=True, error=LimbInputError) % 2:
            raise LimbInputError(f"`n_walkers` must be an even number >= 4, got {self.n_walkers!r}")
        for name in ("chunk", "max_steps", "seed"):
            number(getattr(self, name), f"`{name}`", Range(1 if name != "seed" else 0, 2**32 - 1), integer=True,
                   error=LimbInputError)
        for name in ("max_time_s", "tau_factor", "tau_rtol", "init_scale"):
            number(getattr(self, name), f"`{name}`", POSITIVE, error=LimbInputError)


# =============================================================================== log posterior
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
    n_pixels : number of pixels in the likelihood.
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
        """Model parameters (a container) at a sampled vector ``y``."""
        th = self.theta0.copy()
        th[list(self.free_idx)] = np.asarray(y)[: len(self.free_idx)]
        return self.model.params_type.from_vector(jnp.asarray(th))


def _checked_inputs(model: LimbModel, coords: Any, z: Any, init: LimbParams, fixed: Sequence[str], noise: NoiseModel,
                    sigma: float | None, priors: Priors) -> tuple[np.ndarray, np.ndarray]:
    """The pixels and intensities as float arrays, after every check of :func:`log_posterior` (``LimbInputError``)."""
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
    if not (np.all(np.isfinite(coords)) and np.all(np.isfinite(z))):
        raise LimbInputError("`coords` and `z` must be finite")
    if noise is NoiseModel.KNOWN and not (sigma is not None and np.isfinite(sigma) and sigma > 0):
        raise LimbInputError(f"`sigma` must be > 0 with noise='known', got {sigma!r}")
    return coords, z


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


def log_posterior(model: LimbModel, coords: Any, z: Any, init: LimbParams, *, fixed: Sequence[str] = (),
                  noise: NoiseModel | str = NoiseModel.MARGINAL, sigma: float | None = None,
                  priors: Priors | None = None) -> LogPosterior:
    """Build the jitted (and vmapped) log-posterior of the module docstring.

    Parameters
    ----------
    model, coords, z : the model and the pixels ``(n, 2)`` (``(n,)`` for LINEAR) and intensities.
    init : parameter container; the fixed parameters are held at its values.
    fixed : names of the parameters not sampled.
    noise, sigma : see :class:`NoiseModel`.
    priors : :class:`Priors` (default: positivity bounds only).

    Returns
    -------
    LogPosterior

    Raises
    ------
    LimbInputError
        Shape mismatch, non-finite data, unknown parameter names.
    """
    noise = NoiseModel(noise) if not isinstance(noise, NoiseModel) else noise
    priors = priors or Priors()
    coords, z = _checked_inputs(model, coords, z, init, fixed, noise, sigma, priors)
    free_idx = model.free_indices(fixed)
    q = len(free_idx)
    free_names = tuple(model.param_names[i] for i in free_idx)
    lo, hi, mu, inv_sd = _prior_arrays(free_names, priors)
    theta0 = np.asarray(init.to_vector(), dtype=float)
    n = z.size
    c_j, z_j, th_j = jnp.asarray(coords), jnp.asarray(z), jnp.asarray(theta0)
    lo_j, hi_j, mu_j, isd_j = (jnp.asarray(a) for a in (lo, hi, mu, inv_sd))
    fidx = jnp.asarray(free_idx)
    ptype = model.params_type
    inv_var = 0.0 if sigma is None else 1.0 / float(sigma) ** 2

    def single(y: jax.Array) -> jax.Array:
        yq = y[:q]
        theta = th_j.at[fidx].set(yq)
        r = model.intensity(ptype.from_vector(theta), c_j) - z_j
        s = jnp.sum(r * r)
        if noise is NoiseModel.KNOWN:
            ll = -0.5 * s * inv_var
        elif noise is NoiseModel.MARGINAL:
            ll = -0.5 * n * jnp.log(s)
        else:
            ls = y[q]
            ll = -0.5 * s * jnp.exp(-2.0 * ls) - n * ls
        lp = -0.5 * jnp.sum(((yq - mu_j) * isd_j) ** 2)
        inside = jnp.all(yq > lo_j) & jnp.all(yq < hi_j)
        out = ll + lp
        return jnp.where(inside & jnp.isfinite(out), out, -jnp.inf)

    names = free_names + (("log_sigma",) if noise is NoiseModel.FREE else ())
    return LogPosterior(names, jax.jit(single), jax.jit(jax.vmap(single)), theta0, free_idx, n, model)


# =============================================================================== quality checks
#: Smallest significance ``|ymax - ymin| / sd(ymax - ymin)`` of a limb (a detection with margin
#: for the search over centre and radius: pure noise fits give a few; real limbs hundreds).
MIN_CONTRAST_SIGNIFICANCE = 8.0
#: Largest physical sigmoid steepness (1/px): an edge sharper than 1/1000 px is not resolved by any
#: pixel grid -- k beyond it means the fit put a step through noise.
MAX_K = 1e3
#: Largest ratio of a posterior sd to the fit's Laplace sd: beyond it the walkers ran away.
MAX_STD_RATIO = 100.0


def check_limb_fit(fit_: LimbFit) -> None:
    """Refuse a fit that measured no limb (before any sampling).

    Raises
    ------
    NoBodyError
        Non-finite estimate or covariance, ``k`` above :data:`MAX_K`, or an edge contrast
        ``|ymax - ymin|`` below :data:`MIN_CONTRAST_SIGNIFICANCE` times its standard deviation
        (from the Laplace covariance, floored at ``2 sigma_hat / sqrt(n)``): pure noise.
    """
    p = {k: float(v) for k, v in fit_.params.as_dict().items()}
    cov = np.asarray(fit_.covariance, dtype=float)
    sigma = math.sqrt(max(float(fit_.sigma2), 0.0))
    if not (all(math.isfinite(v) for v in p.values()) and np.all(np.isfinite(cov)) and math.isfinite(sigma)):
        raise NoBodyError("no limb: the fit's estimate or covariance is not finite")
    if "k" in p and not 0.0 < p["k"] <= MAX_K:
        raise NoBodyError(f"no limb: the fitted steepness k = {p['k']:.3g} /px is outside (0, {MAX_K:g}]")
    if "ymax" not in p or "ymin" not in p:
        return
    g = np.array([1.0 if n == "ymax" else -1.0 if n == "ymin" else 0.0 for n in fit_.free])
    n_pix = max(int(fit_.n_pixels), 2)
    sd = math.sqrt(max(float(g @ cov @ g) if g.size else 0.0, 4.0 * sigma**2 / n_pix))
    t = abs(p["ymax"] - p["ymin"]) / sd if sd > 0 else math.inf
    if not t >= MIN_CONTRAST_SIGNIFICANCE:
        raise NoBodyError(f"no limb: the edge contrast |ymax - ymin| = {abs(p['ymax'] - p['ymin']):.3g} is "
                          f"{t:.2f} sd, below {MIN_CONTRAST_SIGNIFICANCE:g} (noise sd {sigma:.3g})")


def check_posterior(post: Posterior, fit_: LimbFit | None = None) -> None:
    """Refuse an improper posterior (after sampling).

    Raises
    ------
    PosteriorImproperError
        A non-finite mean or sd, ``k`` beyond :data:`MAX_K`, or (with the fit) a posterior sd
        more than :data:`MAX_STD_RATIO` times the Laplace sd or a mean further than that many
        Laplace sd from the fit: the walkers ran away from the mode.
    """
    if not (np.all(np.isfinite(post.mean)) and np.all(np.isfinite(post.std))):
        raise PosteriorImproperError("the posterior has non-finite means or sds: the walkers ran away")
    means = post.mean_dict()
    if "k" in means and not 0.0 < means["k"] <= MAX_K:
        raise PosteriorImproperError(f"the posterior mean of k is {means['k']:.3g} /px, outside (0, {MAX_K:g}]")
    if fit_ is None:
        return
    lap = {n: float(s) for n, s in fit_.std.items()}
    est = {n: float(v) for n, v in fit_.params.as_dict().items()}
    for n, sd in post.std_dict().items():
        ref = lap.get(n)
        if ref is None or not ref > 0:
            continue
        if sd > MAX_STD_RATIO * ref or abs(means[n] - est[n]) > MAX_STD_RATIO * ref:
            raise PosteriorImproperError(
                f"the posterior of {n} (mean {means[n]:.4g}, sd {sd:.3g}) is out of all proportion to the fit "
                f"({est[n]:.4g} +- {ref:.3g}): improper posterior")


# =============================================================================== sampling
@dataclass(frozen=True)
class Posterior:
    """Samples and summary of :func:`sample_posterior`.

    Attributes
    ----------
    names : sampled parameter names.
    samples : ``(m, d)`` flat samples after burn-in and thinning.
    mean, std : posterior mean and standard deviation per parameter.
    covariance : ``(d, d)`` sample covariance.
    tau : integrated autocorrelation time per parameter (steps).
    n_steps : chain length (steps per walker).
    converged : the autocorrelation criterion was met (``n_steps > tau_factor max(tau)``
        and ``tau`` stable to ``tau_rtol``).
    burn, thin : burn-in and thinning applied.
    acceptance : mean acceptance fraction.
    wall_s : wall time of the sampling (compilation included).
    tau_history : ``(n_chunks, d)`` ``tau`` after each chunk.
    start : the vector the walkers started around (the fit).
    """

    names: tuple[str, ...]
    samples: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    covariance: np.ndarray
    tau: np.ndarray
    n_steps: int
    converged: bool
    burn: int
    thin: int
    acceptance: float
    wall_s: float
    tau_history: np.ndarray
    start: np.ndarray
    n_walkers: int

    def std_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.std)}

    def mean_dict(self) -> dict[str, float]:
        return {n: float(s) for n, s in zip(self.names, self.mean)}

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (no samples)."""
        return {
            "names": list(self.names),
            "mean": self.mean_dict(),
            "std": self.std_dict(),
            "tau": {n: float(t) for n, t in zip(self.names, self.tau)},
            "n_steps": self.n_steps,
            "n_walkers": self.n_walkers,
            "converged": self.converged,
            "burn": self.burn,
            "thin": self.thin,
            "n_samples": int(self.samples.shape[0]),
            "acceptance": self.acceptance,
            "wall_s": self.wall_s,
        }


def _laplace_start(lp: LogPosterior, start: np.ndarray, cov: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    d = len(lp.names)
    if cov is None:
        scale = np.maximum(1e-3 * np.abs(start), 1e-3)
        return start, np.diag(scale**2)
    c = np.asarray(cov, dtype=float)
    if c.shape != (d, d):
        raise LimbInputError(f"`covariance` must be ({d}, {d}) over {list(lp.names)}, got shape {c.shape}")
    return start, c


def _initial_ball(lp: LogPosterior, start: np.ndarray, cov: np.ndarray, n_walkers: int, scale: float,
                  rng: np.random.Generator) -> np.ndarray:
    try:
        chol = np.linalg.cholesky(0.5 * (cov + cov.T))
        if not np.all(np.isfinite(chol)):
            raise np.linalg.LinAlgError("non-finite covariance")
    except np.linalg.LinAlgError:  # a failed fit's covariance: fall back to a small diagonal ball
        d = np.abs(np.diag(cov)) if np.all(np.isfinite(np.diag(cov))) else np.zeros(start.size)
        chol = np.diag(np.sqrt(np.where(d > 0, d, (1e-3 * np.maximum(np.abs(start), 1.0)) ** 2)))
    p0 = np.empty((n_walkers, start.size))
    filled = 0
    for s in (scale, scale / 10, scale / 100, scale / 1000):
        for _ in range(20):
            cand = start + s * rng.standard_normal((n_walkers, start.size)) @ chol.T
            ok = np.isfinite(lp(cand))
            take = cand[ok][: n_walkers - filled]
            p0[filled : filled + take.shape[0]] = take
            filled += take.shape[0]
            if filled == n_walkers:
                return p0
    raise ConvergenceError(
        "could not place the emcee walkers: the log-posterior is -inf around the start "
        f"{dict(zip(lp.names, start.tolist()))} (check priors/bounds against the fit)"
    )


def sample_posterior(lp: LogPosterior, start: np.ndarray | LimbFit, *, covariance: np.ndarray | None = None,
                     options: PosteriorOptions | None = None, progress: bool = False) -> Posterior:
    """Sample the posterior with emcee until the autocorrelation criterion holds.

    Parameters
    ----------
    lp : from :func:`log_posterior`.
    start : the fit (:class:`~jaxlimb.fitting.LimbFit`, whose estimate and Laplace
        covariance seed the walkers) or a ``(d,)`` start vector over ``lp.names``.
    covariance : ``(d, d)`` covariance of the initial ball for a vector ``start``.
    options : :class:`PosteriorOptions`.
    progress : show a progress bar (steps, with the current max tau and the length it asks for).

    Returns
    -------
    Posterior
        ``converged=False`` if ``max_steps`` or ``max_time_s`` was reached first.

    Raises
    ------
    NoBodyError
        ``start`` is a fit that measured no limb (:func:`check_limb_fit`).
    PosteriorImproperError
        emcee cannot move the ensemble, or the posterior is improper (:func:`check_posterior`).
    """
    import emcee  # the only module that imports emcee (STYLE.md Sec. 1)

    opt = options or PosteriorOptions()
    d = len(lp.names)
    if isinstance(start, LimbFit):
        start_vec, cov = _fit_start(lp, start)
    else:
        start_vec, cov = _laplace_start(lp, np.asarray(start, dtype=float), covariance)
    if start_vec.shape != (d,):
        raise LimbInputError(f"`start` must have shape ({d},) over {list(lp.names)}, got {start_vec.shape}")
    if opt.n_walkers < 2 * d:
        raise LimbInputError(f"`n_walkers` must be >= 2 x {d} parameters, got {opt.n_walkers}")
    rng = np.random.default_rng(opt.seed)
    p0 = _initial_ball(lp, start_vec, cov, opt.n_walkers, opt.init_scale, rng)
    if opt.vectorize:
        fn: Callable[[np.ndarray], Any] = lambda y: np.asarray(lp.batch(y))  # noqa: E731
    else:
        fn = lambda y: float(lp.single(y))  # noqa: E731
    t0 = time.perf_counter()
    sampler = emcee.EnsembleSampler(opt.n_walkers, d, fn, vectorize=opt.vectorize)
    # emcee 3.1 draws from its own RandomState: seed it (reproducible chains)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    taus, converged = _run_until_converged(sampler, p0, opt, progress, t0)
    wall = time.perf_counter() - t0
    tau = taus[-1]
    tau_ok = np.where(np.isfinite(tau), tau, sampler.iteration / 10.0)
    burn = int(min(2 * np.max(tau_ok), sampler.iteration // 2))
    thin = max(1, int(0.5 * np.min(tau_ok)))
    flat = sampler.get_chain(discard=burn, thin=thin, flat=True)
    post = Posterior(
        names=lp.names,
        samples=flat,
        mean=flat.mean(axis=0),
        std=flat.std(axis=0, ddof=1),
        covariance=np.atleast_2d(np.cov(flat, rowvar=False)),
        tau=tau,
        n_steps=int(sampler.iteration),
        converged=converged,
        burn=burn,
        thin=thin,
        acceptance=float(np.mean(sampler.acceptance_fraction)),
        wall_s=wall,
        tau_history=np.asarray(taus),
        start=start_vec,
        n_walkers=opt.n_walkers,
    )
    check_posterior(post, start if isinstance(start, LimbFit) else None)
    return post


def _fit_start(lp: LogPosterior, fit_: LimbFit) -> tuple[np.ndarray, np.ndarray]:
    """Start vector and covariance of the walkers' ball from a fit: its estimate and Laplace covariance over
    the posterior's free parameters (and ``log sigma`` with sd ``1/sqrt(2n)`` when the noise is free)."""
    check_limb_fit(fit_)
    d, q = len(lp.names), len(lp.free_idx)
    free_names = lp.names[:q]
    if tuple(fit_.free) != tuple(free_names):
        raise LimbInputError(f"the fit's free parameters {list(fit_.free)} differ from the posterior's {list(free_names)}")
    vec = np.asarray(fit_.params.to_vector())[list(lp.free_idx)]
    cov = np.asarray(fit_.covariance, dtype=float)
    if d > q:  # FREE noise: append log(sigma_hat) with sd ~ 1/sqrt(2n)
        vec = np.append(vec, 0.5 * math.log(float(fit_.sigma2)))
        c2 = np.zeros((d, d))
        c2[:q, :q] = cov
        c2[q, q] = 1.0 / (2.0 * lp.n_pixels)
        cov = c2
    return vec, cov


def _run_until_converged(sampler: Any, state: np.ndarray, opt: PosteriorOptions, progress: bool,
                         t0: float) -> tuple[list[np.ndarray], bool]:
    """Run ``sampler`` in chunks of ``opt.chunk`` steps until the chain is longer than ``tau_factor``
    autocorrelation times and tau is stable to ``tau_rtol`` (emcee's criterion), or ``max_steps`` /
    ``max_time_s``; returns the tau after each chunk and whether the criterion held."""
    from tqdm.auto import tqdm

    d = state.shape[1]
    taus: list[np.ndarray] = []
    converged = False
    old_tau = np.full(d, np.inf)
    bar = tqdm(total=opt.max_steps, desc="emcee", unit="step", disable=not progress)
    while sampler.iteration < opt.max_steps:
        n = min(opt.chunk, opt.max_steps - sampler.iteration)
        try:
            state = sampler.run_mcmc(state, n)
        except ValueError as e:  # emcee: "Initial state has a large condition number", ...
            raise PosteriorImproperError(f"emcee cannot sample this posterior: {e}") from None
        bar.update(n)
        with np.errstate(invalid="ignore", divide="ignore"):  # a chain of constant walkers early on
            tau = sampler.get_autocorr_time(tol=0)
        taus.append(tau)
        if np.all(np.isfinite(tau)):
            bar.set_postfix(tau_max=f"{np.max(tau):.1f}", need=int(opt.tau_factor * np.max(tau)))
            long_enough = sampler.iteration > opt.tau_factor * np.max(tau)
            stable = np.all(np.abs(old_tau - tau) / tau < opt.tau_rtol)
            if long_enough and stable:
                converged = True
                break
        old_tau = tau
        if time.perf_counter() - t0 > opt.max_time_s:
            break
    bar.close()
    return taus, converged


def vectorize_speedup(lp: LogPosterior, start: np.ndarray | LimbFit, n_steps: int = 200, n_walkers: int = 32,
                      seed: int = 0, covariance: np.ndarray | None = None) -> dict[str, float]:
    """Time ``n_steps`` of emcee with the vectorised log-posterior against one call per walker.

    Both runs are compiled first (a 2-step warm-up each), so the ratio measures the
    per-step cost: one ``vmap`` call per half-ensemble vs ``n_walkers/2`` dispatches.
    Returns ``{"vectorized_s", "per_walker_s", "speedup", "n_steps", "n_walkers"}``.
    """
    out: dict[str, float] = {"n_steps": float(n_steps), "n_walkers": float(n_walkers)}
    for vec, key in ((True, "vectorized_s"), (False, "per_walker_s")):
        warm = PosteriorOptions(n_walkers=n_walkers, chunk=2, max_steps=2,
                                vectorize=vec, seed=seed)
        sample_posterior(lp, start, covariance=covariance, options=warm)
        opt = PosteriorOptions(n_walkers=n_walkers, chunk=n_steps, max_steps=n_steps,
                               vectorize=vec, seed=seed, max_time_s=1e9)
        t0 = time.perf_counter()
        sample_posterior(lp, start, covariance=covariance, options=opt)
        out[key] = time.perf_counter() - t0
    out["speedup"] = out["per_walker_s"] / out["vectorized_s"]
    return out


# =============================================================================== comparison
def compare_uncertainties(post: Posterior, fit: LimbFit | None = None, bound: CramerRao | None = None,
                          truth: LimbParams | None = None) -> dict[str, dict[str, float | None]]:
    """Per parameter: posterior mean and sd, Laplace sd, CRLB sd and their ratios.

    Returns ``{name: {"post_mean", "post_std", "laplace_std", "crlb", "post_over_crlb",
    "post_over_laplace", "laplace_over_crlb", "truth"}}`` (``None`` where not available).
    """
    lap = {} if fit is None else {k: float(v) for k, v in fit.std.items()}
    cr = {} if bound is None else bound.std
    out: dict[str, dict[str, float | None]] = {}
    for i, n in enumerate(post.names):
        ps = float(post.std[i])
        ls, cs = lap.get(n), cr.get(n)
        out[n] = {
            "post_mean": float(post.mean[i]),
            "post_std": ps,
            "laplace_std": ls,
            "crlb": cs,
            "post_over_crlb": ps / cs if cs else None,
            "post_over_laplace": ps / ls if ls else None,
            "laplace_over_crlb": ls / cs if (ls and cs) else None,
            "truth": float(getattr(truth, n)) if (truth is not None and n in truth.field_names()) else None,
        }
    return out


def comparison_table(cmp: Mapping[str, Mapping[str, float | None]]) -> str:
    """Text table of :func:`compare_uncertainties`."""

    def f(v: float | None, w: int = 11, p: int = 5) -> str:
        return f"{'-':>{w}}" if v is None else f"{v:{w}.{p}g}"

    lines = [f"{'param':>9} {'post mean':>11} {'post sd':>11} {'Laplace sd':>11} {'CRLB':>11} {'post/CRLB':>9} {'post/Lapl':>9}"]
    for n, r in cmp.items():
        lines.append(f"{n:>9} {f(r['post_mean'])} {f(r['post_std'])} {f(r['laplace_std'])} {f(r['crlb'])} "
                     f"{f(r['post_over_crlb'], 9, 4)} {f(r['post_over_laplace'], 9, 4)}")
    return "\n".join(lines)


def corner_plot(post: Posterior, path: Any | None = None, truths: Mapping[str, float] | None = None,
                laplace: LimbFit | None = None, title: str | None = None) -> Any:
    """Corner plot of the samples (``corner``), with the truth and the Laplace 1-sigma if given.

    Saves to ``path`` (atomically) when given; returns the figure.
    """
    import corner
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from .._io import atomic_path

    tr = None if truths is None else [truths.get(n) for n in post.names]
    fig = corner.corner(post.samples, labels=list(post.names), truths=tr, show_titles=True, title_fmt=".4f",
                        quantiles=(0.16, 0.5, 0.84))
    if laplace is not None:
        axes = np.asarray(fig.axes).reshape(len(post.names), len(post.names))
        est = np.asarray(laplace.params.to_vector())
        names = laplace.params.field_names()
        for i, n in enumerate(post.names):
            if n in laplace.free:
                s = float(laplace.std[n])
                m = float(est[names.index(n)])
                for v in (m - s, m + s):
                    axes[i, i].axvline(v, color="C1", ls="--", lw=1)
        axes[0, -1].text(0.0, 0.5, "dashed: Laplace $\\pm1\\sigma$", color="C1", transform=axes[0, -1].transAxes)
    if title:
        fig.suptitle(title, fontsize=9)
    if path is not None:
        with atomic_path(str(path)) as tmp:
            fig.savefig(tmp, format=str(path).rsplit(".", 1)[-1], dpi=90)
        plt.close(fig)
    return fig


# =============================================================================== synthetic problems
@dataclass(frozen=True)
class SyntheticLimb:
    """Pixels of a circular-sigmoid limb with exact truth (for studies and tests)."""

    coords: np.ndarray
    z: np.ndarray
    truth: LimbParams
    sigma: float
    arc_deg: float


def synthetic_circle(radius: float = 150.0, k: float = 3.0, ymax: float = 200.0, ymin: float = 20.0,
                     sigma: float = 10.0, arc_deg: float = 360.0, arc_center_deg: float = 0.0,
                     annulus: float = 6.0, center_rc: tuple[float, float] | None = None, seed: int = 0) -> SyntheticLimb:
    """Pixels within ``annulus`` px of a circular limb (Eq. 16), on an arc, plus Gaussian noise.

    The arc is ``arc_deg`` wide, centred on the position angle ``arc_center_deg`` (from
    ``+col`` toward ``-row``): 360 = full disc, 180 = the lit limb of a crescent or gibbous
    Moon (the limb between the cusps is always a half circle), 60 = a short arc.  The
    intensities are the model itself, so the fit's model is exact and the CRLB applies.
    """
    from ..models import CIRCLE, CircleParams

    for name, v in (("radius", radius), ("k", k), ("sigma", sigma), ("annulus", annulus)):
        if not (math.isfinite(v) and v > 0):
            raise LimbInputError(f"`{name}` must be a finite number > 0, got {v!r}")
    if not 0 < arc_deg <= 360:
        raise LimbInputError(f"`arc_deg` must be in (0, 360], got {arc_deg!r}")
    half = radius + annulus + 2
    r0, c0 = center_rc if center_rc is not None else (half + 0.3, half - 0.4)
    rr, cc = np.mgrid[int(np.floor(r0 - half)):int(np.ceil(r0 + half)) + 1, int(np.floor(c0 - half)):int(np.ceil(c0 + half)) + 1]
    rc = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
    d = np.hypot(rc[:, 0] - r0, rc[:, 1] - c0)
    ang = np.degrees(np.arctan2(-(rc[:, 0] - r0), rc[:, 1] - c0))
    dang = (ang - arc_center_deg + 180.0) % 360.0 - 180.0
    sel = (np.abs(d - radius) <= annulus) & (np.abs(dang) <= arc_deg / 2.0)
    rc = rc[sel]
    truth = CircleParams(float(r0), float(c0), float(radius), float(k), float(ymax), float(ymin))
    clean = np.asarray(CIRCLE.intensity(truth, jnp.asarray(rc)))
    z = clean + sigma * np.random.default_rng(seed).standard_normal(clean.size)
    return SyntheticLimb(rc, z, truth, float(sigma), float(arc_deg))


__all__ = [
    "LogPosterior",
    "NoiseModel",
    "Posterior",
    "PosteriorOptions",
    "Priors",
    "compare_uncertainties",
    "comparison_table",
    "corner_plot",
    "log_posterior",
    "priors_from_hints",
    "sample_posterior",
    "SyntheticLimb",
    "synthetic_circle",
    "vectorize_speedup",
]
