"""The track subpackage on a tiny drawn transfer: dynamics, STM, filter + smoother, gating, batch fit,
self-calibration and its observability report.  One module-scoped sequence so that the compiled programs are
shared (diffrax + jacfwd compile once)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from jaxlimb.geometry.ephemeris import body_position
from jaxlimb.track import (
    average_band,
    drawn_frames,
    fit_arc,
    nees,
    nominal_noise,
    run_filter,
)

from .conftest import THETA, N

# compiling diffrax + jacfwd through it (filter, batch, self-calibration) dominates: ~1-2 min on 2 cores
slow = pytest.mark.slow


def test_table_matches_the_ephemeris(setup):
    arc, _, _ = setup
    t = 12345.6  # between nodes
    want = body_position("moon", arc.jd0 + t / 86400.0)
    assert np.max(np.abs(arc.body_position("moon", np.array([t]))[0] - want)) < 1e-3


@slow
def test_stm_is_the_derivative_of_the_flow(setup):
    _, prop, tr = setup
    x = jnp.asarray(tr.x0)
    _, Phi = prop.step_with_stm(x, jnp.asarray(0.0), jnp.asarray(7200.0))
    h = np.array([1.0] * 3 + [1e-4] * 3)
    for i in (0, 4):
        e = np.zeros(6)
        e[i] = h[i]
        d = (np.asarray(prop.step(x + e, 0.0, 7200.0)) - np.asarray(prop.step(x - e, 0.0, 7200.0))) / (2 * h[i])
        np.testing.assert_allclose(np.asarray(Phi)[:, i], d, rtol=1e-6, atol=1e-9)


@slow
def test_transfer_reaches_its_flyby(setup):
    arc, _, tr = setup
    moon = arc.body_position("moon", tr.t[-1:])[0]
    assert abs(np.linalg.norm(tr.states[-1, :3] - moon) - 40_000.0) < 1.0


@slow
def test_filter_smoother_consistent_and_gate(setup):
    _, prop, tr = setup
    rng = np.random.default_rng(7)
    fr = drawn_frames(tr, nominal_noise(tr), rng)
    fr.z[9, 0] += 40.0  # a frame measured 40 px off: the gate must drop it
    P0 = np.diag([500.0**2] * 3 + [5e-3**2] * 3)
    x0 = tr.x0 + np.linalg.cholesky(P0) @ rng.standard_normal(6)
    res = run_filter(fr, prop, x0, P0, 0.0)
    assert not res.used[9] and res.used.sum() == N - 1
    assert res.nis[9] > 100 * res.gate
    e_s = nees(res.x_smooth, res.P_smooth, tr.states)
    assert np.mean(e_s) < 3 * 6  # one run: loose, the Monte Carlo is benchmarks/track_transfer.py
    assert np.all(np.sqrt(np.trace(res.P_smooth[:, :3, :3], axis1=1, axis2=2)) < np.sqrt(np.trace(P0[:3, :3])))


@slow
def test_batch_self_calibration_and_observability(setup):
    _, prop, tr = setup
    rng = np.random.default_rng(11)
    nominal = THETA * np.array([1.01, 1, 1, 1]) + np.array([0.0, 2.0, -1.5, 0.0])
    fr = drawn_frames(tr, nominal_noise(tr), rng, theta_nominal=nominal)
    guess = tr.x0 + np.array([300.0, -200.0, 100.0, 1e-3, -2e-3, 1e-3])
    fit = fit_arc(fr, prop, 0.0, guess, calibrate=True)
    cam = fit.camera
    assert fit.observability is not None and set(cam) == {"focal_px", "principal_r", "principal_c", "k1"}
    for i, n in enumerate(("focal_px", "principal_r", "principal_c")):
        assert cam[n] is not None, n
        assert abs(cam[n]["value"] - THETA[i]) < 4 * cam[n]["sigma"], n
    assert abs(cam["focal_px"]["value"] / THETA[0] - 1) < 1e-3
    if cam["k1"] is None:  # reported as a direction, not as a number
        dirs = fit.observability.unobservable_directions()
        assert dirs and max(abs(d["k1"]) for d in dirs) > 0.9
    # the state-only fit with the wrong camera is visibly worse
    fit0 = fit_arc(fr, prop, 0.0, guess, max_outlier_fraction=1.0, max_passes=1)
    assert fit0.residual_rms > 3 * fit.residual_rms


def test_average_band():
    lo, hi = average_band(50, 6)
    assert lo < 6 < hi and hi - lo < 2.0
