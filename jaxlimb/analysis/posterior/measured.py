r"""The posterior of what :func:`jaxlimb.pipeline.locate` measured: its final fit's model and nuisance parameters
sampled, and the samples mapped to the body centre, radius, range and line of sight through ``locate``'s own
body-centre mapping.

The likelihood is that of the fit ``locate`` ran (:func:`jaxlimb.analysis.located.located_fit`: the same model --
by default the physical lunar-Lambert profile with its widenings --, pixels, weights and held parameters), the noise
marginalised (Jeffreys) or known (``sigma``).  That posterior knows the pixel noise only.  On a scene the model does
not describe exactly (another reflectance law, albedo spots, another PSF) the data carry a model error the
likelihood does not, and its credible regions are too small by the ratio ``locate``'s covariance already accounts
for (the cluster-robust and specification terms of :mod:`jaxlimb.model_error`).  The *adjusted* posterior is
the open-faced sandwich of Shaby (2014, J. Comput. Graph. Stat. 23(3), 853-876): every sample moved to
:math:`\hat\theta + \Omega(\theta - \hat\theta)` with :math:`\Omega = C^{1/2}\Sigma^{-1/2}` (symmetric square roots),
``C`` ``locate``'s covariance of the fit's parameters and :math:`\Sigma` the samples' covariance: the posterior's
shape, ``locate``'s spread.  Both are reported beside ``locate``'s covariance and the Cramér--Rao bound, and
:func:`credible_level` says where the truth of a rendered scene falls in each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..located import LocatedFit
from .likelihood import log_posterior
from .sampler import Posterior, PosteriorOptions, sample_posterior

#: The mapped quantities of a round body's answer, and their names in ``locate``'s covariance.
MAPPED = (("center_r", "center_r"), ("center_c", "center_c"), ("radius", "radius"), ("range_km", "range_km"))


def _sqrtm(a: np.ndarray, inverse: bool = False) -> np.ndarray:
    w, v = np.linalg.eigh(0.5 * (a + a.T))
    w = np.maximum(w, 1e-300)
    return (v * (w ** (-0.5 if inverse else 0.5))) @ v.T


def sandwich_adjust(samples: np.ndarray, estimate: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Shaby's open-faced sandwich (module docstring): ``estimate + Omega (samples - estimate)`` whose covariance is
    ``target``.

    Parameters
    ----------
    samples : np.ndarray (m, d)
        Posterior samples.
    estimate : np.ndarray (d,)
        The point the samples are scaled about (the fit's estimate).
    target : np.ndarray (d, d)
        Covariance the adjusted samples get (``locate``'s).

    Returns
    -------
    np.ndarray (m, d)
        Adjusted samples: the posterior's shape, ``target``'s spread.
    """
    omega = _sqrtm(target) @ _sqrtm(np.atleast_2d(np.cov(samples, rowvar=False)), inverse=True)
    return estimate + (samples - estimate) @ omega.T


@dataclass(frozen=True)
class MeasuredPosterior:
    """The posterior of ``locate``'s fit (module docstring).

    Attributes
    ----------
    posterior : the samples of the fit's free parameters (the likelihood's posterior).
    adjusted : the same samples adjusted to ``locate``'s covariance (:func:`sandwich_adjust`).
    mapped, mapped_adjusted : ``{quantity: (m,)}`` samples of the body centre (``center_r``, ``center_c``), radius
        and range through ``locate``'s mapping (a thinned subset of ``m`` samples).
    located : the fit (:class:`~jaxlimb.analysis.located.LocatedFit`).
    """

    posterior: Posterior
    adjusted: np.ndarray
    mapped: dict[str, np.ndarray]
    mapped_adjusted: dict[str, np.ndarray]
    located: LocatedFit

    def compare(self) -> dict[str, dict[str, float | None]]:
        """Per mapped quantity: ``locate``'s value and sigma, the CRLB, the posterior's mean and sd (raw and
        adjusted) and their ratios to ``locate``'s sigma.

        Returns
        -------
        dict
            ``{quantity: {"locate", "locate_sd", "crlb", "post_mean", "post_sd", "adjusted_mean", "adjusted_sd",
            "post_over_locate", "adjusted_over_locate"}}`` for ``center_r``, ``center_c`` (px), ``radius`` (px) and
            ``range_km`` where mapped; ``None`` where not available.
        """
        lf = self.located
        est = {"center_r": lf.measurement.center_rc[0], "center_c": lf.measurement.center_rc[1],
               "radius": lf.measurement.radius_px, "range_km": lf.measurement.range_km}
        out: dict[str, dict[str, float | None]] = {}
        for q, name in MAPPED:
            if q not in self.mapped or name not in lf.names:
                continue
            i = lf.names.index(name)
            sd = math.sqrt(max(float(lf.matrix[i, i]), 0.0))
            raw, adj = self.mapped[q], self.mapped_adjusted[q]
            out[q] = {"locate": est[q], "locate_sd": sd, "crlb": (lf.crlb or {}).get(name),
                      "post_mean": float(raw.mean()), "post_sd": float(raw.std(ddof=1)),
                      "adjusted_mean": float(adj.mean()), "adjusted_sd": float(adj.std(ddof=1)),
                      "post_over_locate": float(raw.std(ddof=1)) / sd if sd > 0 else None,
                      "adjusted_over_locate": float(adj.std(ddof=1)) / sd if sd > 0 else None}
        return out

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the chain, the parameters' posterior and the mapped comparison.

        Returns
        -------
        dict
            ``model``, ``free``, ``chain`` (:meth:`Posterior.summary`) and ``comparison`` (:meth:`compare`).
        """
        return {"model": self.located.model.name, "free": list(self.located.free), "chain": self.posterior.summary(),
                "comparison": self.compare()}


def _mapped(lf: LocatedFit, vectors: np.ndarray) -> dict[str, np.ndarray]:
    """Free-parameter vectors through ``locate``'s body-centre mapping (:meth:`LocatedFit.mapped`)."""
    theta0 = np.asarray(lf.params.to_vector(), float)
    idx = [lf.model.param_names.index(n) for n in lf.free]
    rows = []
    for v in vectors:
        th = theta0.copy()
        th[idx] = v[: len(idx)]
        m = lf.mapped(lf.model.params_type.from_vector(th))
        rows.append((m["center_rc"][0], m["center_rc"][1], np.nan if m["radius_px"] is None else m["radius_px"],
                     np.nan if m["range_km"] is None else m["range_km"]))
    a = np.asarray(rows, float)
    return {q: a[:, j] for j, (q, _) in enumerate(MAPPED) if np.all(np.isfinite(a[:, j]))}


def measured_posterior(lf: LocatedFit, options: PosteriorOptions | None = None, *, noise: str = "marginal",
                       n_mapped: int = 1000, progress: bool = False) -> MeasuredPosterior:
    """Sample the posterior of ``locate``'s fit ``lf`` and map it (module docstring).

    The walkers start around ``locate``'s estimate with its noise-only covariance.

    Parameters
    ----------
    lf : LocatedFit
        From :func:`~jaxlimb.analysis.located.located_fit`.
    options : PosteriorOptions, optional
        Sampler settings; default ``PosteriorOptions()``.
    noise : {"marginal", "known"}
        Noise marginalised (Jeffreys) or known at the fit's residual sigma.
    n_mapped : int
        Samples mapped to the body centre (evenly thinned).
    progress : bool
        Show the sampler's progress bar.

    Returns
    -------
    MeasuredPosterior
        The samples, the adjusted samples and both mapped.

    Raises
    ------
    PosteriorImproperError
        emcee cannot move the ensemble, or the posterior is improper
        (:func:`~jaxlimb.analysis.posterior.check_posterior`).
    ConvergenceError
        The walkers cannot be placed (the log-posterior is -inf around the estimate).
    """
    data, fixed = lf.data, tuple(lf.final.fixed)
    lp = log_posterior(lf.model, data.coords, data.z, lf.params, fixed=fixed, noise=noise,
                       sigma=lf.sigma if noise == "known" else None, weights=data.weights)
    theta = np.asarray(lf.params.to_vector(), float)
    est = theta[[lf.model.param_names.index(n) for n in lf.free]]
    post = sample_posterior(lp, est, covariance=np.asarray(lf.final.covariance_noise, float), options=options,
                            progress=progress)
    adjusted = sandwich_adjust(post.samples, est, np.asarray(lf.final.fit.covariance, float))
    pick = np.unique(np.linspace(0, post.samples.shape[0] - 1, min(n_mapped, post.samples.shape[0])).astype(int))
    return MeasuredPosterior(post, adjusted, _mapped(lf, post.samples[pick]), _mapped(lf, adjusted[pick]), lf)


def credible_level(samples: np.ndarray, truth: np.ndarray) -> float:
    """The smallest credible level whose region holds ``truth``.

    The fraction of ``samples`` closer to the samples' mean than ``truth`` is, in the Mahalanobis distance of the
    samples' covariance: ``truth`` is inside the ``q`` region when this is ``<= q``; over scenes drawn from the prior
    it is uniform for a calibrated posterior.

    Parameters
    ----------
    samples : np.ndarray (m, k)
        Samples of ``k`` quantities (``(m,)`` for one).
    truth : np.ndarray (k,)
        The true value.

    Returns
    -------
    float
        Credible level in [0, 1].
    """
    s = np.atleast_2d(np.asarray(samples, float).T).T
    mean = s.mean(axis=0)
    inv = np.linalg.inv(np.atleast_2d(np.cov(s, rowvar=False)))
    d2 = np.einsum("ij,jk,ik->i", s - mean, inv, s - mean)
    e = np.atleast_1d(np.asarray(truth, float)) - mean
    return float(np.mean(d2 < e @ inv @ e))


def truth_levels(mp: MeasuredPosterior, center_rc: Any, radius_px: float | None = None) -> dict[str, float]:
    """Where a scene's truth falls: the credible levels (:func:`credible_level`) of the true body centre and radius in
    the posterior and in the adjusted posterior, and in ``locate``'s own Gaussian (its NEES as a chi-square level).

    Parameters
    ----------
    mp : MeasuredPosterior
        The posterior of ``locate``'s fit.
    center_rc : array (2,)
        True body centre, (row, col) px.
    radius_px : float, optional
        True apparent radius (px).

    Returns
    -------
    dict of str to float
        ``center``, ``center_adjusted``, ``center_locate`` and, with ``radius_px``, ``radius`` and ``radius_adjusted``.
    """
    lf = mp.located
    t = np.asarray(center_rc, float)
    out = {"center": credible_level(np.column_stack([mp.mapped["center_r"], mp.mapped["center_c"]]), t),
           "center_adjusted": credible_level(np.column_stack([mp.mapped_adjusted["center_r"],
                                                              mp.mapped_adjusted["center_c"]]), t)}
    idx = [lf.names.index("center_r"), lf.names.index("center_c")]
    e = t - np.asarray(lf.measurement.center_rc, float)
    out["center_locate"] = float(1.0 - math.exp(-0.5 * float(e @ np.linalg.solve(lf.matrix[np.ix_(idx, idx)], e))))
    if radius_px is not None and "radius" in mp.mapped:
        out["radius"] = credible_level(mp.mapped["radius"][:, None], np.array([radius_px]))
        out["radius_adjusted"] = credible_level(mp.mapped_adjusted["radius"][:, None], np.array([radius_px]))
    return out


__all__ = ["MAPPED", "MeasuredPosterior", "credible_level", "measured_posterior", "sandwich_adjust", "truth_levels"]
