"""Tests of the emcee posterior (jaxlimb.analysis.posterior)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxlimb.analysis.crlb import crlb
from jaxlimb.analysis.posterior import (
    NoiseModel,
    PosteriorOptions,
    Priors,
    compare_uncertainties,
    comparison_table,
    corner_plot,
    log_posterior,
    priors_from_hints,
    sample_posterior,
    synthetic_circle,
)
from jaxlimb.errors import LimbInputError
from jaxlimb.fitting import fit
from jaxlimb.models import CIRCLE

FIXED = ("k", "ymax", "ymin")


@pytest.fixture(scope="module")
def problem():
    s = synthetic_circle(radius=40.0, annulus=4.0, sigma=10.0, seed=3)
    init = s.truth.replace(r0=s.truth.r0 + 0.4, radius=s.truth.radius - 0.3)
    f = fit(CIRCLE, s.coords, s.z, init, fixed=FIXED)
    return s, f


@pytest.fixture(scope="module")
def posterior(problem):
    s, f = problem
    lp = log_posterior(CIRCLE, s.coords, s.z, f.params, fixed=FIXED, noise="known", sigma=s.sigma)
    return sample_posterior(lp, f, options=PosteriorOptions(n_walkers=16, seed=1, max_time_s=60.0))


def test_converges_and_matches_crlb(problem, posterior):
    s, f = problem
    assert posterior.converged
    assert posterior.n_steps > 50 * posterior.tau.max()
    assert posterior.samples.shape[1] == 3
    bound = crlb(CIRCLE, s.coords, s.truth, s.sigma, fixed=FIXED)
    cmp = compare_uncertainties(posterior, f, bound, s.truth)
    for name in ("r0", "c0", "radius"):
        assert cmp[name]["post_over_crlb"] == pytest.approx(1.0, abs=0.10), comparison_table(cmp)
        # the posterior mean is the fit to within a fraction of its sd (linear-Gaussian regime)
        assert abs(cmp[name]["post_mean"] - float(getattr(f.params, name))) < 0.2 * cmp[name]["post_std"]
    assert "post/CRLB" in comparison_table(cmp)


def test_vectorized_chain_equals_per_walker_chain(problem):
    s, f = problem
    lp = log_posterior(CIRCLE, s.coords, s.z, f.params, fixed=FIXED, noise="marginal")
    runs = [
        sample_posterior(lp, f, options=PosteriorOptions(n_walkers=8, chunk=15, max_steps=15, seed=5, vectorize=v))
        for v in (True, False)
    ]
    np.testing.assert_allclose(runs[0].samples, runs[1].samples, rtol=0, atol=1e-9)
    assert not runs[0].converged  # 15 steps cannot satisfy N > 50 tau


def test_log_posterior_formulas(problem):
    s, f = problem
    y = np.asarray(f.params.to_vector())[:3] + np.array([0.01, -0.02, 0.03])
    theta = np.asarray(s.truth.to_vector()).copy()
    theta[:3] = y
    model = np.asarray(CIRCLE.intensity(CIRCLE.params_type.from_vector(theta), s.coords))
    ssq = float(np.sum((model - s.z) ** 2))
    n = s.z.size
    init = s.truth  # fixed k, ymax, ymin at the truth
    known = log_posterior(CIRCLE, s.coords, s.z, init, fixed=FIXED, noise=NoiseModel.KNOWN, sigma=7.0)
    marg = log_posterior(CIRCLE, s.coords, s.z, init, fixed=FIXED, noise="marginal")
    free = log_posterior(CIRCLE, s.coords, s.z, init, fixed=FIXED, noise="free")
    assert free.names == ("r0", "c0", "radius", "log_sigma")
    assert float(known(y)) == pytest.approx(-0.5 * ssq / 49.0, rel=1e-12)
    assert float(marg(y)) == pytest.approx(-0.5 * n * math.log(ssq), rel=1e-12)
    ls = math.log(9.0)
    assert float(free(np.append(y, ls))) == pytest.approx(-0.5 * ssq / 81.0 - n * ls, rel=1e-12)
    # Gaussian prior adds -((x - mu)/sd)^2 / 2; bounds give -inf
    pri = log_posterior(CIRCLE, s.coords, s.z, init, fixed=FIXED, noise="known", sigma=7.0,
                        priors=Priors(gaussian={"radius": (40.5, 0.25)}, bounds={"r0": (0.0, 50.0)}))
    assert float(pri(y)) - float(known(y)) == pytest.approx(-0.5 * ((y[2] - 40.5) / 0.25) ** 2, rel=1e-10)
    assert float(pri(np.array([50.5, y[1], y[2]]))) == -np.inf
    assert float(known(np.array([y[0], y[1], -1.0]))) == -np.inf  # radius > 0 always
    # the vmapped batch equals the single evaluations
    pts = np.stack([y, y + 0.05, y - 0.05])
    np.testing.assert_allclose(known(pts), [float(known(p)) for p in pts], rtol=1e-13)


def test_radius_prior_shrinks_posterior(problem, posterior):
    s, f = problem
    sd_like = float(posterior.std[2])
    pri = Priors(gaussian={"radius": (float(s.truth.radius), sd_like)})  # equal information -> sd / sqrt(2)
    lp = log_posterior(CIRCLE, s.coords, s.z, f.params, fixed=FIXED, noise="known", sigma=s.sigma, priors=pri)
    post = sample_posterior(lp, f, options=PosteriorOptions(n_walkers=16, seed=2, tau_factor=30.0, max_time_s=60.0))
    assert post.std[2] / sd_like == pytest.approx(1 / math.sqrt(2), abs=0.08)


def test_not_converged_is_reported(problem):
    s, f = problem
    lp = log_posterior(CIRCLE, s.coords, s.z, f.params, fixed=FIXED, noise="marginal")
    post = sample_posterior(lp, f, options=PosteriorOptions(n_walkers=8, chunk=50, max_steps=100))
    assert not post.converged and post.n_steps == 100
    assert post.summary()["converged"] is False


def test_priors_from_hints_and_errors(problem):
    s, f = problem
    pri = priors_from_hints({"expected_radius_px": 40.0, "expected_radius_uncertainty_frac": 0.05, "x": 1}, CIRCLE)
    assert pri.gaussian == {"radius": (40.0, 2.0)}
    assert priors_from_hints({}, CIRCLE).gaussian == {}
    with pytest.raises(LimbInputError, match="sigma"):
        log_posterior(CIRCLE, s.coords, s.z, f.params, noise="known")
    with pytest.raises(LimbInputError, match="unknown parameter 'a'"):
        log_posterior(CIRCLE, s.coords, s.z, f.params, priors=Priors(gaussian={"a": (1.0, 1.0)}))
    with pytest.raises(LimbInputError, match="sd > 0"):
        Priors(gaussian={"radius": (1.0, 0.0)})
    with pytest.raises(LimbInputError, match="n_walkers"):
        PosteriorOptions(n_walkers=7)


def test_corner_plot_writes_png(posterior, problem, tmp_path):
    s, f = problem
    out = tmp_path / "corner.png"
    corner_plot(posterior, out, truths=s.truth.as_dict(), laplace=f, title="test")
    assert out.stat().st_size > 10_000


def test_cli_posterior_center_rc_path(tmp_path, capsys):
    import json

    import jax.numpy as jnp

    from jaxlimb.cli import main
    from jaxlimb.models import CircleParams

    truth = CircleParams(40.2, 41.7, 25.0, 2.0, 180.0, 30.0)
    rr, cc = np.mgrid[0:82, 0:84]
    grid = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
    img = np.asarray(CIRCLE.intensity(truth, jnp.asarray(grid))).reshape(rr.shape)
    img = img + 10.0 * np.random.default_rng(0).standard_normal(img.shape)
    path = tmp_path / "img.npy"
    np.save(path, img)
    png = tmp_path / "corner.png"
    code = main(["posterior", str(path), "--center-rc", "40.5", "41.5", "--radius", "25.3", "--annulus", "4",
                 "--fix", "k,ymax,ymin", "--noise", "known", "--sigma", "10", "--walkers", "16", "--json",
                 "--plot", str(png)])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["status"] == "ok", out
    assert out["posterior"]["names"] == ["r0", "c0", "radius"]
    assert out["posterior"]["converged"] is True
    for n, v in (("r0", 40.2), ("c0", 41.7), ("radius", 25.0)):
        c = out["comparison"][n]
        assert abs(c["post_mean"] - v) < 5 * c["post_std"]
    assert png.stat().st_size > 10_000
    code = main(["posterior", str(path), "--center-rc", "40", "41", "--radius", "25", "--fix", "q", "--json"])
    err = json.loads(capsys.readouterr().out)
    assert code == 2 and err["status"] == "error" and "q" in err["message"]
