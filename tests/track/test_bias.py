"""Bias states per body (:mod:`jaxlimb.track.bias`): their prior from the model-error part of the measurement
covariance, the biased image, and a drawn sequence whose Moon centres carry a known offset along the Sun:
the filter with the bias states recovers it and stays consistent, the filter without them does not."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb.track import (
    Frames,
    nees,
    predict,
    run_filter,
)
from jaxlimb.track.bias import apparent_radius_px, bias_model
from jaxlimb.track.measurement import sun_direction_px
from jaxlimb.track.scenario import perturb_attitudes, true_measurements

from .conftest import THETA, N

NOISE_PX, MODEL_PX = 0.03, 0.1  # per-frame noise and model-error sigma of the centre and the radius (px)
MOON_SUN_OFFSET = 5e-3  # the injected bias: the Moon's centre moved along the Sun by 0.5 % of its radius


def _covariances(tr, sigma_px: float) -> np.ndarray:  # noqa: ANN001
    z = true_measurements(tr)
    out = []
    for k, b in enumerate(tr.bodies):
        size = THETA[0] * np.tan(np.arcsin(6378.137 / z[k, 2])) if b == "earth" else z[k, 2]
        s3 = z[k, 2] * sigma_px / size if b == "earth" else sigma_px
        out.append(np.diag([sigma_px**2, sigma_px**2, s3**2]))
    return np.array(out)


def _frames(arc, tr, rng: np.random.Generator, offset: float) -> Frames:  # noqa: ANN001
    """Measurements with the noise of ``NOISE_PX``, the Moon's centres moved by ``offset`` (sun_offset), and the
    covariance ``locate`` would report: noise plus the model error of ``MODEL_PX``."""
    sun = arc.body_position("sun", tr.t)
    bp = tr.body_positions()
    is_range = np.array([1.0 if b == "earth" else 0.0 for b in tr.bodies])
    radius = np.array([6378.137 if b == "earth" else 1737.4 for b in tr.bodies])
    z = np.array([np.asarray(predict(jnp.asarray(tr.states[k, :3]), jnp.asarray(THETA), jnp.asarray(tr.C_true[k]),
                                     jnp.asarray(bp[k]), radius[k], is_range[k], THETA[0], jnp.asarray(sun[k]),
                                     jnp.asarray([offset * (b == "moon"), 0.0]))) for k, b in enumerate(tr.bodies)])
    noise = _covariances(tr, NOISE_PX)
    z = z + np.einsum("kij,kj->ki", np.linalg.cholesky(noise), rng.standard_normal(z.shape))
    R = noise + _covariances(tr, MODEL_PX)
    return Frames(t=tr.t.copy(), z=z, R=R, C=perturb_attitudes(tr.C_true, 1e-6, rng), body_pos=bp, radius_km=radius,
                  is_range=is_range, f_nominal=np.full(N, THETA[0]), theta=np.tile(THETA, (N, 1)),
                  attitude_sigma=np.full(N, 1e-6), labels=tuple(f"f{k}" for k in range(N)), sun_pos=sun, R_noise=noise)


def test_sun_direction_in_the_image():
    # the Sun to the camera's +x (the image's +column) of a body on the boresight
    d = np.asarray(sun_direction_px(jnp.array([0.0, 0.0, 1e5]), jnp.array([1e8, 0.0, 1e5])))
    np.testing.assert_allclose(d, [0.0, 1.0], atol=1e-12)
    d = np.asarray(sun_direction_px(jnp.array([0.0, 0.0, 1e5]), jnp.array([0.0, -3e7, 2e8])))
    np.testing.assert_allclose(d, [-1.0, 0.0], atol=1e-12)


def test_prior_is_the_model_error_part(setup):
    arc, _, tr = setup
    fr = _frames(arc, tr, np.random.default_rng(0), 0.0)
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
        fr = _frames(arc, tr, rng, MOON_SUN_OFFSET)
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
