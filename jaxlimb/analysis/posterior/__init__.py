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
Burn-in is ``2 max(tau)`` and thinning ``max(1, min(tau)/2)``.  ``moves="laplace"``: an independence
Metropolis-Hastings proposal from a multivariate t around the fit (:func:`laplace_move`), for posteriors close to
Gaussian (``tau`` of a few steps).

Layout: :mod:`.likelihood` (noise models, priors, the jitted log-posterior), :mod:`.sampler` (emcee, the checks),
:mod:`.report` (the comparison table), :mod:`.plots` (the corner plot), :mod:`.synthetic` (limbs with exact truth),
:mod:`.measured` (the posterior of ``locate``'s fit).

What ``locate`` measured.  :func:`measured_posterior` samples the model and nuisance parameters of the fit
``locate`` ran (:mod:`.measured`; the physical limb profile by default) and maps the samples to the body centre,
radius and range through ``locate``'s own mapping, beside ``locate``'s covariance and the Cramér--Rao bound, with
the model-error adjustment of the open-faced sandwich (Shaby 2014).

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

``benchmarks/posterior_study.py`` measures the chains' convergence and wall time on limbs from a full
circle to short arcs, and the vectorised log-posterior's speed-up over one call per walker
(``docs/validation/uncertainty.md``).

References
----------
.. [1] D. Mortari, C. N. D'Souza, R. Zanetti, "Image Processing of Illuminated Ellipsoid",
   J. Spacecraft and Rockets 53(3), 2016, doi:10.2514/1.A33342.
.. [2] Aerospace 2015 (vol. 2), Moon image processing: gradient, RANSAC, circular sigmoid
   (``/work/shared/papers/aerospace-2015-moon-gradient-ransac-csf.md``), Sec. 7.
.. [3] D. Foreman-Mackey et al., "emcee: The MCMC Hammer", PASP 125, 306 (2013),
   doi:10.1086/670067; J. Goodman, J. Weare, CAMCoS 5(1), 65 (2010).
"""

from .likelihood import LogPosterior, NoiseModel, Priors, log_posterior, priors_from_hints
from .measured import MAPPED, MeasuredPosterior, credible_level, measured_posterior, sandwich_adjust, truth_levels
from .plots import corner_plot, plot_measured
from .report import compare_uncertainties, comparison_table
from .sampler import (MAX_K, MAX_STD_RATIO, MIN_CONTRAST_SIGNIFICANCE, Posterior, PosteriorOptions, check_limb_fit,
                      check_posterior, laplace_move, sample_posterior, vectorize_speedup)
from .synthetic import SyntheticLimb, synthetic_circle

__all__ = [
    "MAPPED",
    "MAX_K",
    "MAX_STD_RATIO",
    "MIN_CONTRAST_SIGNIFICANCE",
    "LogPosterior",
    "MeasuredPosterior",
    "NoiseModel",
    "Posterior",
    "PosteriorOptions",
    "Priors",
    "SyntheticLimb",
    "check_limb_fit",
    "check_posterior",
    "compare_uncertainties",
    "comparison_table",
    "corner_plot",
    "credible_level",
    "laplace_move",
    "log_posterior",
    "measured_posterior",
    "plot_measured",
    "priors_from_hints",
    "sample_posterior",
    "sandwich_adjust",
    "synthetic_circle",
    "truth_levels",
    "vectorize_speedup",
]
