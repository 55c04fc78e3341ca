r"""Sampling a limb fit's posterior with emcee (module docstring of :mod:`jaxlimb.analysis.posterior`): the options,
the walkers' start, the stretch and Laplace moves, the autocorrelation criterion, and the quality checks before and
after sampling."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ConvergenceError, LimbInputError, NoBodyError, PosteriorImproperError
from ...fitting import LimbFit
from .likelihood import LogPosterior


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
    moves: str = "stretch"
    """emcee's moves: ``"stretch"`` (the affine-invariant stretch move alone) or ``"laplace"`` (an independence
    Metropolis-Hastings proposal from a multivariate t around the start, with its covariance -- :func:`laplace_move`
    -- mixed with the stretch move, 0.8 / 0.2: where the posterior is close to Gaussian, ``tau`` ~ 1-3 steps
    instead of ~50; where it is not, the stretch move and the autocorrelation criterion still decide)."""
    seed: int = 0
    """Seed of the initial ball and of emcee's generator."""

    def __post_init__(self) -> None:
        from ..._validate import POSITIVE, Range, number

        if number(self.n_walkers, "`n_walkers`", Range(4, 100_000), integer=True, error=LimbInputError) % 2:
            raise LimbInputError(f"`n_walkers` must be an even number >= 4, got {self.n_walkers!r}")
        for name in ("chunk", "max_steps", "seed"):
            number(getattr(self, name), f"`{name}`", Range(1 if name != "seed" else 0, 2**32 - 1), integer=True,
                   error=LimbInputError)
        for name in ("max_time_s", "tau_factor", "tau_rtol", "init_scale"):
            number(getattr(self, name), f"`{name}`", POSITIVE, error=LimbInputError)
        if self.moves not in ("stretch", "laplace"):
            raise LimbInputError(f"`moves` must be 'stretch' or 'laplace', got {self.moves!r}")


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
        """Posterior standard deviation per parameter.

        Returns
        -------
        dict of str to float
            ``{name: sd}`` in the parameters' units.
        """
        return {n: float(s) for n, s in zip(self.names, self.std)}

    def mean_dict(self) -> dict[str, float]:
        """Posterior mean per parameter.

        Returns
        -------
        dict of str to float
            ``{name: mean}``.
        """
        return {n: float(s) for n, s in zip(self.names, self.mean)}

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (no samples).

        Returns
        -------
        dict
            ``names``, ``mean``, ``std``, ``tau`` (per parameter), ``n_steps``, ``n_walkers``, ``converged``,
            ``burn``, ``thin``, ``n_samples``, ``acceptance`` and ``wall_s``.
        """
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

    Parameters
    ----------
    fit_ : LimbFit
        The fit whose estimate and Laplace covariance would seed the walkers.

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

    Parameters
    ----------
    post : Posterior
        The sampled posterior.
    fit_ : LimbFit, optional
        The fit the walkers started from; without it only finiteness and ``k`` are checked.

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


def laplace_move(mean: np.ndarray, cov: np.ndarray, df: float = 5.0, scale: float = 1.2) -> Any:
    """An independence Metropolis-Hastings move for emcee: proposals from a multivariate t (``df`` degrees of
    freedom) around ``mean`` with covariance ``scale^2 cov`` (heavier tails than the posterior's Laplace
    approximation, so the ratio of target to proposal stays bounded); the log-ratio of the proposal densities
    makes it exact (Hastings 1970; Tierney 1994, Ann. Stat. 22(4), "independence chains").

    Parameters
    ----------
    mean : np.ndarray (d,)
        Centre of the proposal (the fit's estimate).
    cov : np.ndarray (d, d)
        Its covariance (the fit's Laplace covariance); must be positive definite.
    df : float
        Degrees of freedom of the t distribution.
    scale : float
        Factor on the proposal's standard deviations.

    Returns
    -------
    emcee.moves.MHMove
        The move, for ``emcee.EnsembleSampler(..., moves=...)``.
    """
    import emcee

    d = mean.size
    chol = np.linalg.cholesky(scale * scale * 0.5 * (cov + cov.T))
    inv = np.linalg.inv(chol)

    def log_q(x: np.ndarray) -> np.ndarray:
        u = (x - mean) @ inv.T
        return -0.5 * (df + d) * np.log1p(np.sum(u * u, axis=1) / df)

    def proposal(coords: np.ndarray, random: Any) -> tuple[np.ndarray, np.ndarray]:
        k = coords.shape[0]
        z = random.standard_normal((k, d)) @ chol.T / np.sqrt(random.chisquare(df, k) / df)[:, None]
        new = mean + z
        return new, log_q(coords) - log_q(new)

    return emcee.moves.MHMove(proposal)


def _emcee(lp: LogPosterior, opt: PosteriorOptions, start: np.ndarray, cov: np.ndarray, rng: np.random.Generator):
    """The seeded ``emcee.EnsembleSampler`` of ``opt`` (vectorised or not; its moves)."""
    import emcee  # the only module that imports emcee (STYLE.md Sec. 1)

    if opt.vectorize:
        fn: Callable[[np.ndarray], Any] = lambda y: np.asarray(lp.batch(y))  # noqa: E731
    else:
        fn = lambda y: float(lp.single(y))  # noqa: E731
    moves = None if opt.moves == "stretch" else [(laplace_move(start, cov), 0.8), (emcee.moves.StretchMove(), 0.2)]
    sampler = emcee.EnsembleSampler(opt.n_walkers, len(lp.names), fn, vectorize=opt.vectorize, moves=moves)
    # emcee 3.1 draws from its own RandomState: seed it (reproducible chains)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    return sampler


def sample_posterior(lp: LogPosterior, start: np.ndarray | LimbFit, *, covariance: np.ndarray | None = None,
                     options: PosteriorOptions | None = None, progress: bool = False) -> Posterior:
    """Sample the posterior with emcee until the autocorrelation criterion holds.

    Parameters
    ----------
    lp : LogPosterior
        From :func:`~jaxlimb.analysis.posterior.log_posterior`.
    start : LimbFit or np.ndarray (d,)
        The fit (its estimate and Laplace covariance seed the walkers) or a start vector over ``lp.names``.
    covariance : np.ndarray (d, d), optional
        Covariance of the initial ball (and of the ``"laplace"`` move) for a vector ``start``; default a
        diagonal of ``(1e-3 max(|start|, 1))^2``.
    options : PosteriorOptions, optional
        Default ``PosteriorOptions()``.
    progress : bool
        Show a progress bar (steps, with the current max tau and the length it asks for).

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

    Examples
    --------
    The centre and radius of a synthetic circular limb (Eq. 16 of Mortari et al. 2016; radius 30 px, noise
    10 DN), the edge's steepness and levels held; a short chain (a study runs until ``converged``):

    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> import numpy as np
    >>> from jaxlimb.analysis.posterior import log_posterior, synthetic_circle
    >>> from jaxlimb.models import CIRCLE
    >>> limb = synthetic_circle(radius=30.0, sigma=10.0, seed=1)
    >>> lp = log_posterior(CIRCLE, limb.coords, limb.z, limb.truth, fixed=("k", "ymax", "ymin"))
    >>> start = np.array([limb.truth.r0, limb.truth.c0, limb.truth.radius])
    >>> opt = PosteriorOptions(n_walkers=8, chunk=100, max_steps=200, seed=0)
    >>> post = sample_posterior(lp, start, covariance=np.diag([1e-4, 1e-4, 1e-4]), options=opt)
    >>> post.names, post.n_steps, post.converged
    (('r0', 'c0', 'radius'), 200, False)
    >>> round(post.mean_dict()["radius"], 2), round(post.std_dict()["radius"], 3)
    (30.0, 0.006)
    """
    opt = options or PosteriorOptions()
    start_vec, cov = _start_and_covariance(lp, start, covariance, opt.n_walkers)
    rng = np.random.default_rng(opt.seed)
    p0 = _initial_ball(lp, start_vec, cov, opt.n_walkers, opt.init_scale, rng)
    t0 = time.perf_counter()
    sampler = _emcee(lp, opt, start_vec, cov, rng)
    taus, converged = _run_until_converged(sampler, p0, opt, progress, t0)
    post = _collect(sampler, lp, taus, converged, time.perf_counter() - t0, start_vec, opt.n_walkers)
    check_posterior(post, start if isinstance(start, LimbFit) else None)
    return post


def _start_and_covariance(lp: LogPosterior, start: np.ndarray | LimbFit, covariance: np.ndarray | None,
                          n_walkers: int) -> tuple[np.ndarray, np.ndarray]:
    """The validated start vector of :func:`sample_posterior` and the covariance of its initial ball (for a vector
    ``start`` without ``covariance`` a diagonal of ``(1e-3 max(|start|, 1))^2``)."""
    d = len(lp.names)
    if isinstance(start, LimbFit):
        start_vec, cov = _fit_start(lp, start)
    elif covariance is None:
        start_vec = np.asarray(start, dtype=float)
        scale = np.maximum(1e-3 * np.abs(start_vec), 1e-3)
        cov = np.diag(scale**2)
    else:
        start_vec, cov = np.asarray(start, dtype=float), np.asarray(covariance, dtype=float)
        if cov.shape != (d, d):
            raise LimbInputError(f"`covariance` must be ({d}, {d}) over {list(lp.names)}, got shape {cov.shape}")
    if start_vec.shape != (d,):
        raise LimbInputError(f"`start` must have shape ({d},) over {list(lp.names)}, got {start_vec.shape}")
    if n_walkers < 2 * d:
        raise LimbInputError(f"`n_walkers` must be >= 2 x {d} parameters, got {n_walkers}")
    return start_vec, cov


def _collect(sampler: Any, lp: LogPosterior, taus: list[np.ndarray], converged: bool, wall: float, start: np.ndarray,
             n_walkers: int) -> Posterior:
    """The :class:`Posterior` of a finished chain: burn-in ``2 max(tau)``, thinning ``max(1, min(tau)/2)``."""
    tau = taus[-1]
    tau_ok = np.where(np.isfinite(tau), tau, sampler.iteration / 10.0)
    burn = int(min(2 * np.max(tau_ok), sampler.iteration // 2))
    thin = max(1, int(0.5 * np.min(tau_ok)))
    flat = sampler.get_chain(discard=burn, thin=thin, flat=True)
    return Posterior(names=lp.names, samples=flat, mean=flat.mean(axis=0), std=flat.std(axis=0, ddof=1),
                     covariance=np.atleast_2d(np.cov(flat, rowvar=False)), tau=tau, n_steps=int(sampler.iteration),
                     converged=converged, burn=burn, thin=thin, acceptance=float(np.mean(sampler.acceptance_fraction)),
                     wall_s=wall, tau_history=np.asarray(taus), start=start, n_walkers=n_walkers)


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

    Parameters
    ----------
    lp : LogPosterior
        The posterior to sample.
    start : np.ndarray (d,) or LimbFit
        As :func:`sample_posterior`.
    n_steps : int
        Timed steps per run.
    n_walkers : int
        Ensemble size (even, >= 2 d).
    seed : int
        Seed of both runs.
    covariance : np.ndarray (d, d), optional
        As :func:`sample_posterior`.

    Returns
    -------
    dict of str to float
        ``vectorized_s``, ``per_walker_s`` (seconds), ``speedup`` (their ratio), ``n_steps``, ``n_walkers``.
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


__all__ = ["MAX_K", "MAX_STD_RATIO", "MIN_CONTRAST_SIGNIFICANCE", "Posterior", "PosteriorOptions", "check_limb_fit",
           "check_posterior", "laplace_move", "sample_posterior", "vectorize_speedup"]
