"""Bias states per body (:mod:`jaxlimb.track.bias`): their prior from the model-error part of the measurement
covariance, the biased image, and a drawn sequence whose Moon centres carry a known offset along the Sun:
the filter with the bias states recovers it and stays consistent, the filter without them does not."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb.track import Frames, nees, run_filter
from jaxlimb.track.bias import apparent_radius_px, bias_model
from jaxlimb.track.measurement import sun_direction_px

from .conftest import MODEL_PX, N, locate_like_frames

MOON_SUN_OFFSET = 5e-3  # the injected bias: the Moon's centre moved along the Sun by 0.5 % of its radius


def test_sun_direction_in_the_image():
    # the Sun to the camera's +x (the image's +column) of a body on the boresight
    d = np.asarray(sun_direction_px(jnp.array([0.0, 0.0, 1e5]), jnp.array([1e8, 0.0, 1e5])))
    np.testing.assert_allclose(d, [0.0, 1.0], atol=1e-12)
    d = np.asarray(sun_direction_px(jnp.array([0.0, 0.0, 1e5]), jnp.array([0.0, -3e7, 2e8])))
    np.testing.assert_allclose(d, [-1.0, 0.0], atol=1e-12)


def test_prior_is_the_model_error_part(setup):
    arc, _, tr = setup
    fr = locate_like_frames(arc, tr, np.random.default_rng(0), 0.0)
    bm = bias_model(fr)
    assert bm.names == ("earth.sun_offset", "earth.scale", "moon.sun_offset", "moon.scale")
    size = apparent_radius_px(fr)
    moon = fr.is_range == 0
    # the centre's model-error sigma over the radius, the size's over the size (median over the body's frames)
    np.testing.assert_allclose(bm.sigma[2], np.sqrt(np.median((MODEL_PX / size[moon]) ** 2)), rtol=1e-9)
    np.testing.assert_allclose(bm.sigma[3], np.sqrt(np.median((MODEL_PX / fr.z[moon, 2]) ** 2)), rtol=1e-2)
    np.testing.assert_allclose(bm.sigma[1], np.sqrt(np.median((MODEL_PX / size[~moon]) ** 2)), rtol=1e-2)
    assert bm.select.shape == (N, 2, 4) and np.all(bm.select.sum(axis=(1, 2)) == 2)
    # no split into noise and model error, or asked not to: no bias state
    assert len(bias_model(Frames(**{**fr.__dict__, "R_noise": None}))) == 0
    assert len(bias_model(fr, enabled=False)) == 0
    assert len(bias_model(Frames(**{**fr.__dict__, "R_noise": fr.R}))) == 0


@pytest.mark.slow
def test_bias_state_recovers_a_moon_offset(setup):
    arc, prop, tr = setup
    P0 = np.diag([500.0**2] * 3 + [5e-3**2] * 3)
    with_b, without, est = [], [], []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        fr = locate_like_frames(arc, tr, rng, MOON_SUN_OFFSET)
        x0 = tr.x0 + np.linalg.cholesky(P0) @ rng.standard_normal(6)
        res = run_filter(fr, prop, x0, P0, 0.0)
        with_b.append(nees(res.x_smooth[-1], res.P_smooth[-1], tr.states[-1]))
        i = res.bias.names.index("moon.sun_offset")
        est.append((res.b_smooth[i] - MOON_SUN_OFFSET) / np.sqrt(res.b_smooth_cov[i, i]))
        res0 = run_filter(fr, prop, x0, P0, 0.0, bias=False)
        without.append(nees(res0.x_smooth[-1], res0.P_smooth[-1], tr.states[-1]))
    assert np.all(np.abs(est) < 3.5), est  # the offset is recovered inside its sigma
    assert np.mean(with_b) < 14.0, with_b  # chi2(6) average of 4 runs: 95 % below ~10
    assert np.mean(without) > 3 * np.mean(with_b), (without, with_b)
