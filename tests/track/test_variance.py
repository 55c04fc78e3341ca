"""The split of the bodies' model error (:mod:`jaxlimb.track.variance`): the walk's columns are a random walk,
the bound marginalises the walking biases, and on drawn sequences whose model error is known to be independent,
or a constant Moon offset, the restricted likelihood finds which it is; the batch fit with a walk agrees with the
smoother."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from jaxlimb.track import filter_with_split, fit_arc, nees, posterior_crlb, run_filter, variance_split
from jaxlimb.track.bias import BiasModel, bias_model, random_effects, walk_columns
from jaxlimb.track.measurement import noise_covariance
from jaxlimb.track.scenario import true_measurements

from .conftest import locate_like_frames

def test_walk_columns_are_a_random_walk():
    rng = np.random.default_rng(1)
    t = np.array([0.0, 1.0, 2.5, 4.0, 7.0, 8.0])
    E = np.zeros((6, 3, 2))
    E[[1, 3, 4], :, 0] = rng.standard_normal((3, 3))  # state 0 seen by frames 1, 3, 4
    E[[0, 2, 5], :, 1] = rng.standard_normal((3, 3))
    sigma, walk = np.array([0.3, 0.0]), np.array([0.02, 0.05])
    W = random_effects(E, t, BiasModel(("a.x", "b.x"), sigma, np.zeros((6, 2, 2)), walk))
    cov = np.einsum("kim,ljm->kilj", W, W)
    for k in range(6):
        for l in range(6):
            want = sum(np.outer(E[k, :, j], E[l, :, j]) * (sigma[j] ** 2 + walk[j] * (min(t[k], t[l]) - t[0]))
                       for j in range(2))
            np.testing.assert_allclose(cov[k, :, l, :], want, atol=1e-12)
    _, owner = walk_columns(E, t)
    assert list(owner) == [0, 0, 0, 1, 1]  # frame 0 starts state 1's walk at t[0]: no increment


def test_bound_with_a_walk_is_wider(setup):
    arc, prop, tr = setup
    fr = locate_like_frames(arc, tr, np.random.default_rng(0), 0.0, independent=1.0)
    P0 = np.diag([500.0**2] * 3 + [5e-3**2] * 3)
    bm = bias_model(fr)
    still = posterior_crlb(fr, prop, tr.x0, 0.0, P0, bias=bm)
    walking = posterior_crlb(fr, prop, tr.x0, 0.0, P0, bias=BiasModel(bm.names, bm.sigma, bm.select,
                                                                       bm.sigma**2 / (tr.t[-1] - tr.t[0])))
    none = posterior_crlb(fr, prop, tr.x0, 0.0, P0, bias=False)
    tr3 = [np.trace(p[:, :3, :3], axis1=1, axis2=2).mean() for p in (none, still, walking)]
    assert tr3[0] < tr3[1] < tr3[2], tr3


@pytest.mark.slow
def test_split_finds_independent_and_common_error(setup):
    arc, prop, tr = setup
    P0 = np.diag([500.0**2] * 3 + [5e-3**2] * 3)
    indep, common, err_default, err_split, nees_split = [], [], [], [], []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        x0 = tr.x0 + np.linalg.cholesky(P0) @ rng.standard_normal(6)
        fr = locate_like_frames(arc, tr, rng, 0.0, independent=1.0)  # all of the model error independent from frame to frame
        split = variance_split(fr, prop, tr.x0, 0.0, bias_model(fr))
        indep.append(split.alpha)
        fr = locate_like_frames(arc, tr, rng, 5e-3)  # none independent: a constant Moon offset
        split = variance_split(fr, prop, tr.x0, 0.0, bias_model(fr))
        moon = split.bodies.index("moon")
        common.append((split.alpha[moon], split.beta[moon] + split.gamma[moon]))
        frs, bm, res, _ = filter_with_split(fr, prop, (0.0, x0, P0), True)
        nees_split.append(nees(res.x_smooth[-1], res.P_smooth[-1], tr.states[-1]))
        base = filter_with_split(fr, prop, (0.0, x0, P0), False)[2]
        err_default.append(np.linalg.norm(base.x_smooth[:, :3] - tr.states[:, :3], axis=1).mean())
        err_split.append(np.linalg.norm(res.x_smooth[:, :3] - tr.states[:, :3], axis=1).mean())
    assert np.mean(indep) > 0.6, indep  # independent model error: found independent
    alpha_moon, shared = np.array(common).T
    assert np.mean(alpha_moon) < 0.3 and np.mean(shared) > 0.1, common  # a constant offset: found common
    assert np.mean(nees_split) < 14.0, nees_split  # chi2(6) average of 4 runs: 95 % below ~10
    assert np.mean(err_split) < np.mean(err_default), (err_split, err_default)


def test_the_shares_divide_locates_whole_model_error(setup):
    # the arc cannot size a common part that moves the image as the trajectory would: it only divides locate's
    # model error, all of it, between the independent, constant and walking parts
    arc, prop, tr = setup
    rng = np.random.default_rng(5)
    for offset, independent in ((0.0, 1.0), (5e-3, 0.0)):
        fr = locate_like_frames(arc, tr, rng, offset, independent=independent)
        bm = bias_model(fr)
        split = variance_split(fr, prop, tr.x0, 0.0, bm)
        with_states = [split.bodies.index(n.split(".")[0]) for n in bm.names]
        np.testing.assert_allclose((split.alpha + split.beta + split.gamma)[with_states], 1.0, atol=1e-12)
        assert np.all((split.alpha >= 0) & (split.beta >= 0) & (split.gamma >= 0))


def test_batch_with_a_walk_agrees_with_the_smoother(setup):
    # the batch marginalises the walk as the filter models it: with the same prior and deterministic dynamics,
    # the estimate and its sigma are the smoother's (a linear-Gaussian arc: batch = smoother)
    arc, prop, tr = setup
    P0 = np.diag([500.0**2] * 3 + [5e-3**2] * 3)
    rng = np.random.default_rng(3)
    fr = locate_like_frames(arc, tr, rng, 5e-3)
    bm = bias_model(fr)
    walking = BiasModel(bm.names, bm.sigma * 0.5, bm.select, 0.5 * bm.sigma**2 / (tr.t[-1] - tr.t[0]))
    x0 = tr.x0 + np.linalg.cholesky(P0) @ rng.standard_normal(6)
    res = run_filter(fr, prop, x0, P0, 0.0, q=0.0, bias=walking)  # deterministic dynamics, as the batch
    fit = fit_arc(fr, prop, 0.0, res.x_smooth[0], bias=walking, prior=(x0, P0))
    still = fit_arc(fr, prop, 0.0, res.x_smooth[0], bias=BiasModel(bm.names, bm.sigma * 0.5, bm.select), prior=(x0, P0))
    sig = np.sqrt(np.diag(fit.P0))
    assert np.all(np.abs(fit.x0 - res.x_smooth[0]) < 0.03 * sig), (fit.x0 - res.x_smooth[0]) / sig
    np.testing.assert_allclose(sig, np.sqrt(np.diag(res.P_smooth[0])), rtol=0.01)
    assert np.all(np.diag(fit.P0)[:3] > np.diag(still.P0)[:3])  # the walk widens the arc's covariance


def test_a_body_whose_every_frame_was_gated_keeps_locates_covariance(setup):
    arc, prop, tr = setup
    fr = locate_like_frames(arc, tr, np.random.default_rng(3), 0.0, independent=1.0)
    bm = bias_model(fr)
    moon = fr.radius_km < 3000.0  # the Moon's frames (1737 km); the Earth's are 6378 km
    assert moon.any() and (~moon).any()
    split = variance_split(fr, prop, tr.x0, 0.0, bm, used=~moon)  # the gate refused every Moon frame
    i = split.bodies.index("moon")
    assert split.alpha[i] == 1.0 and split.beta[i] == 0.0 and split.gamma[i] == 0.0
    applied, kept = split.apply(fr, bm)  # every frame, the Moon's too: its covariance is locate's own
    np.testing.assert_allclose(applied.R[moon], fr.R[moon])
    assert not any(n.startswith("moon.") for n in kept.names)


def test_a_filter_that_used_almost_no_frame_has_no_split(setup):
    # a camera far from the one the frames were measured with: the gate refuses all but one frame, whose three
    # measurements do not outnumber the state; the restricted likelihood has nothing to split (it was NaN)
    arc, prop, tr = setup
    fr = locate_like_frames(arc, tr, np.random.default_rng(3), 0.0, independent=1.0)
    used = np.zeros(len(fr), bool)
    used[1] = True
    assert variance_split(fr, prop, tr.x0, 0.0, bias_model(fr), used=used) is None
    used[[2, 3]] = True  # nine measurements: a split
    assert variance_split(fr, prop, tr.x0, 0.0, bias_model(fr), used=used) is not None


def test_the_split_with_correlated_noise_finds_no_model_error(setup):
    # a partly lit body's centre and size are correlated, in the noise and in the model error alike (near rank
    # one, along the Sun's image): errors drawn from the noise alone leave no independent model error
    arc, prop, tr = setup
    rng = np.random.default_rng(11)

    def correlations() -> np.ndarray:
        u = rng.choice([-1.0, 1.0], (len(tr.t), 3)) * rng.uniform(0.5, 1.0, (len(tr.t), 3))
        C = 0.03 * np.eye(3) + u[:, :, None] * u[:, None, :]
        return C / np.sqrt(np.einsum("kii->ki", C)[:, :, None] * np.einsum("kii->ki", C)[:, None, :])

    alpha = []
    for _ in range(3):
        fr = locate_like_frames(arc, tr, rng, 0.0)
        s, m = (np.sqrt(np.einsum("kii->ki", c)) for c in (fr.R_noise, fr.R - fr.R_noise))
        noise, model = (correlations() * v[:, :, None] * v[:, None, :] for v in (s, m))
        z = true_measurements(tr) + np.einsum("kij,kj->ki", np.linalg.cholesky(noise), rng.standard_normal(fr.z.shape))
        fr = replace(fr, z=z, R=noise + model, R_noise=noise)
        alpha.append(variance_split(fr, prop, tr.x0, 0.0, bias_model(fr)).alpha.max())
    assert np.mean(alpha) < 0.05, alpha


def test_frames_take_the_noise_covariance_with_its_correlations():
    names = ("center_r", "center_c", "radius")
    N = np.array([[4.0, 1.0, 3.0], [1.0, 2.0, -1.0], [3.0, -1.0, 9.0]])
    m = {"crlb": {a: float(np.sqrt(N[i, i])) for i, a in enumerate(names)},
         "covariance_noise": {a: {b: float(N[i, j]) for j, b in enumerate(names)} for i, a in enumerate(names)}}
    np.testing.assert_allclose(noise_covariance(m, names), N)
    np.testing.assert_allclose(noise_covariance({"crlb": m["crlb"]}, names), np.diag(np.diag(N)))  # older answers
    assert noise_covariance({}, names) is None
