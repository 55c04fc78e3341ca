"""The fit behind ``locate``'s answer (jaxlimb.analysis.located) and the posterior of it
(jaxlimb.analysis.posterior.measured): the same answer, the samples through ``locate``'s mapping, the model-error
adjustment, the truth's credible level; the Laplace independence moves and the weighted likelihood."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from jaxlimb.analysis.posterior import (PosteriorOptions, credible_level, log_posterior, sample_posterior,
                                        sandwich_adjust)
from jaxlimb.models import CIRCLE, CircleParams


@functools.lru_cache(maxsize=1)
def _located():
    from jaxlimb.analysis.located import located_fit
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging import Hints
    from jaxlimb.render import RenderOptions, moon_scene, render_body

    cam = Camera(focal_length_mm=16.0 * 500 / 2592, rows=400, cols=500)
    sc = moon_scene(30000.0, 40.0, center_rc=(190.0, 260.0), camera=cam, sun_angle_deg=30.0)
    img, truth = render_body(sc, cam, RenderOptions(psf_sigma_px=1.0, bit_depth=8, read_noise_e=160.0), seed=3)
    hints = Hints(body="moon", sun_dir_camera=tuple(float(v) for v in truth.sun_dir_cam))
    return located_fit(img, cam, hints), truth


@pytest.mark.slow
def test_located_fit_is_the_fit_behind_locates_answer():
    lf, truth = _located()
    assert lf.model.name.startswith("lunar_limb")  # the physical profile: locate's default with the Sun known
    np.testing.assert_allclose(lf.geo.center_rc, lf.measurement.center_rc, atol=1e-9)
    m = lf.mapped(lf.params)  # the estimate through locate's mapping: locate's centre, radius and range
    np.testing.assert_allclose(m["center_rc"], lf.measurement.center_rc, atol=1e-9)
    assert m["radius_px"] == pytest.approx(lf.measurement.radius_px, abs=1e-9)
    assert {"center_r", "center_c", "radius"} <= set(lf.names) and lf.matrix.shape == (len(lf.names),) * 2
    assert abs(lf.measurement.center_rc[0] - truth.center_rc[0]) < 0.2


@pytest.mark.slow
def test_measured_posterior_maps_samples_and_adjusts_to_locates_covariance():
    from jaxlimb.analysis.posterior import measured_posterior, truth_levels

    lf, truth = _located()
    mp = measured_posterior(lf, PosteriorOptions(n_walkers=16, moves="laplace", chunk=40, max_steps=80, seed=2),
                            n_mapped=200)
    cmp = mp.compare()
    assert {"center_r", "center_c", "radius"} <= set(cmp)
    for q in ("center_r", "center_c"):
        r = cmp[q]
        assert abs(r["post_mean"] - r["locate"]) < 3 * r["post_sd"]  # the posterior sits on locate's answer
        assert r["adjusted_sd"] == pytest.approx(r["locate_sd"], rel=0.25)  # the sandwich: locate's spread
        assert r["crlb"] is not None and r["crlb"] > 0
    lv = truth_levels(mp, truth.center_rc, truth.apparent_radius_px)
    assert set(lv) >= {"center", "center_adjusted", "center_locate", "radius", "radius_adjusted"}
    assert all(0.0 <= v <= 1.0 for v in lv.values())


def test_sandwich_adjust_gives_the_target_covariance():
    rng = np.random.default_rng(1)
    s = rng.multivariate_normal([1.0, 2.0], [[1.0, 0.3], [0.3, 0.5]], size=20000)
    target = np.array([[4.0, -1.0], [-1.0, 2.0]])
    a = sandwich_adjust(s, np.array([1.0, 2.0]), target)
    np.testing.assert_allclose(np.cov(a, rowvar=False), target, rtol=1e-10)
    np.testing.assert_allclose(a.mean(axis=0), [1.0, 2.0], atol=0.05)


def test_credible_level_is_uniform_for_a_calibrated_posterior():
    """Truths drawn from the posterior itself: their levels are uniform (68 % inside the 68 % region)."""
    rng = np.random.default_rng(2)
    cov = np.array([[1.0, 0.4], [0.4, 0.8]])
    samples = rng.multivariate_normal([0.0, 0.0], cov, size=4000)
    levels = np.array([credible_level(samples, t) for t in rng.multivariate_normal([0.0, 0.0], cov, size=400)])
    assert np.mean(levels <= 0.6827) == pytest.approx(0.6827, abs=0.06)
    assert np.mean(levels <= 0.9545) == pytest.approx(0.9545, abs=0.03)
    assert credible_level(samples, np.array([10.0, 10.0])) == 1.0


def _circle(seed=0, n=40):
    rr, cc = np.mgrid[0:n, 0:n]
    rc = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
    truth = CircleParams(20.3, 19.6, 12.0, 2.0, 150.0, 20.0)
    z = np.asarray(CIRCLE.intensity(truth, rc)) + 5.0 * np.random.default_rng(seed).standard_normal(rc.shape[0])
    return rc, z, truth


def test_weights_and_padding_of_the_log_posterior():
    """A pixel of weight 0 does not count; the padding to a bucket changes nothing; a weight scales a residual."""
    rc, z, truth = _circle()
    y = np.asarray(truth.to_vector())
    full = log_posterior(CIRCLE, rc, z, truth, noise="known", sigma=5.0)
    w = np.ones(z.size)
    w[:10] = 0.0
    part = log_posterior(CIRCLE, rc, z, truth, noise="known", sigma=5.0, weights=w)
    drop = log_posterior(CIRCLE, rc[10:], z[10:], truth, noise="known", sigma=5.0)
    assert part.n_pixels == drop.n_pixels == z.size - 10
    assert float(part(y)) == pytest.approx(float(drop(y)), rel=1e-12)
    r = np.asarray(CIRCLE.intensity(truth, rc)) - z
    assert float(full(y)) == pytest.approx(-0.5 * np.sum(r * r) / 25.0, rel=1e-12)
    two = log_posterior(CIRCLE, rc, z, truth, noise="known", sigma=5.0, weights=np.full(z.size, 2.0))
    assert float(two(y)) == pytest.approx(4.0 * float(full(y)), rel=1e-12)


def test_laplace_moves_sample_the_same_posterior_with_a_short_autocorrelation():
    rc, z, truth = _circle(seed=3)
    fixed = ("k", "ymax", "ymin")
    from jaxlimb.fitting import fit

    f = fit(CIRCLE, rc, z, truth, fixed=fixed)
    lp = log_posterior(CIRCLE, rc, z, f.params, fixed=fixed, noise="known", sigma=5.0)
    lap = sample_posterior(lp, f, options=PosteriorOptions(n_walkers=16, moves="laplace", chunk=50, seed=1))
    assert lap.converged and np.max(lap.tau) < 10.0 and lap.acceptance > 0.4
    np.testing.assert_allclose(lap.std, np.sqrt(np.diag(np.asarray(f.covariance))), rtol=0.15)
