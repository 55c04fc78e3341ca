"""The Monte Carlo of the pipeline (jaxlimb.analysis.pipeline_study): one trial's numbers from a measurement, the
per-family summary (bias, RMS, NEES, coverage of the reported ellipses) and its figure."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from jaxlimb.analysis.montecarlo import MonteCarloOptions, run_monte_carlo
from jaxlimb.analysis.pipeline_study import CHI2_2, FamilyTrial, measurement_errors, pipeline_summary, plot_pipeline
from jaxlimb.errors import LimbInputError


def _measurement(err=(0.03, -0.04), sig=(0.02, 0.05), rho=0.3):
    c = rho * sig[0] * sig[1]
    cov = {"center_r": {"center_r": sig[0] ** 2, "center_c": c}, "center_c": {"center_r": c, "center_c": sig[1] ** 2},
           "radius": {"radius": 0.01**2}, "range_km": {"range_km": 25.0}}
    truth = SimpleNamespace(body_center_rc=(100.0, 200.0), apparent_radius_px=50.0, range_km=150000.0)
    m = SimpleNamespace(center_rc=(100.0 + err[0], 200.0 + err[1]), covariance=cov, radius_px=50.02, range_km=150010.0,
                        iterations=12, crlb={"center_r": 0.01, "center_c": 0.012, "radius": 0.008})
    return m, truth, np.array(err), np.array([[sig[0] ** 2, c], [c, sig[1] ** 2]])


def test_measurement_errors_are_the_errors_the_nees_and_the_bounds():
    m, truth, e, P = _measurement()
    out = measurement_errors(m, truth)
    assert out["row"] == pytest.approx(0.03) and out["col"] == pytest.approx(-0.04)
    assert out["nees"] == pytest.approx(float(e @ np.linalg.solve(P, e)), rel=1e-12)
    assert out["radius"] == pytest.approx(0.02) and out["sigma_radius"] == pytest.approx(0.01)
    assert out["range_pct"] == pytest.approx(100 * 10.0 / 150000.0) and out["range_z"] == pytest.approx(2.0)
    assert out["crlb_row"] == 0.01 and out["iterations"] == 12.0


def _trial(seed: int, i: int) -> dict[str, float]:
    """Gaussian errors whose covariance is the reported one: a calibrated pipeline (NEES ~ chi-square 2)."""
    rng = np.random.default_rng(seed)
    sig = (0.02, 0.05)
    e = rng.standard_normal(2) * sig
    m, truth, _, _ = _measurement(err=tuple(e), sig=sig, rho=0.0)
    return {**measurement_errors(m, truth), "family": float(i % 2)}


def test_summary_of_a_calibrated_study(tmp_path):
    res = run_monte_carlo(_trial, MonteCarloOptions(n_trials=400, chunk_size=100, seed=5, progress=False))
    s = pipeline_summary(res, ("own", "hapke"))
    assert set(s) == {"all", "own", "hapke"} and s["own"]["n"] == s["hapke"]["n"] == 200
    assert s["all"]["nees_mean"] == pytest.approx(2.0, abs=0.3)
    assert s["all"]["coverage"]["68"] == pytest.approx(0.6827, abs=0.06)
    assert s["all"]["coverage"]["95"] == pytest.approx(0.9545, abs=0.03)
    assert s["all"]["row"]["rms"] == pytest.approx(0.02, rel=0.15)
    assert s["all"]["crlb_row_mean"] == pytest.approx(0.01)
    assert CHI2_2["68"] == pytest.approx(-2 * math.log(1 - 0.6827))
    plot_pipeline(res, s, tmp_path / "p.png", title="calibrated")
    assert (tmp_path / "p.png").stat().st_size > 1000


def test_family_trial_checks_its_families():
    assert FamilyTrial(("own", "hapke")).families == ("own", "hapke")
    with pytest.raises(LimbInputError, match="families"):
        FamilyTrial(("own", "nope"))
    with pytest.raises(LimbInputError, match="body"):
        FamilyTrial(("own",), body="mars")
