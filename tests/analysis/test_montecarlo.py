"""Tests of the Monte-Carlo engine (jaxlimb.analysis.montecarlo)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jaxlimb.analysis.figures import plot_errors, plot_rms_vs_crlb
from jaxlimb.analysis.montecarlo import (
    MonteCarloOptions,
    load_monte_carlo,
    run_monte_carlo,
    stats_json,
    trial_seed,
)
from jaxlimb.errors import ConfigError, LimbInputError, TooThinError


def gaussian_trial(seed: int, i: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    return {"x": 1.0 + 0.5 * rng.standard_normal(), "y": rng.standard_normal(), "n_steps": 3 + i % 3}


def test_trials_independent_of_chunking(tmp_path):
    a = run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=23, chunk_size=5, seed=7, progress=False))
    b = run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=23, chunk_size=23, seed=7, progress=False,
                                                          out_dir=str(tmp_path / "b")))
    np.testing.assert_array_equal(a.values["x"], b.values["x"])
    np.testing.assert_array_equal(a.seeds, [trial_seed(7, i) for i in range(23)])
    c = run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=23, chunk_size=5, seed=8, progress=False))
    assert not np.any(a.values["x"] == c.values["x"])
    assert len(set(a.seeds.tolist())) == 23


def test_resume_skips_finished_chunks_and_loses_only_the_running_one(tmp_path):
    out = tmp_path / "study"
    calls: list[int] = []
    first = {"run": True}

    def flaky(seed: int, i: int) -> dict[str, float]:
        calls.append(i)
        if i == 12 and first.pop("run", False):  # interrupt inside chunk 2 on the first run
            raise RuntimeError("killed")  # not a JaxlimbError: stops the run, like an interrupt
        return gaussian_trial(seed, i)

    opt = MonteCarloOptions(n_trials=20, chunk_size=5, seed=1, out_dir=str(out), progress=False)
    with pytest.raises(RuntimeError, match="killed"):
        run_monte_carlo(flaky, opt)
    assert sorted(p.name for p in out.glob("chunk_*.npz")) == ["chunk_000000.npz", "chunk_000001.npz"]
    assert not list(out.glob(".*tmp"))  # nothing half-written left behind
    calls.clear()
    res = run_monte_carlo(flaky, opt)
    assert calls == list(range(10, 20))  # only the unfinished chunks ran
    assert (res.chunks_run, res.chunks_skipped) == (2, 2)
    full = run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=20, chunk_size=5, seed=1, progress=False))
    np.testing.assert_array_equal(res.values["x"], full.values["x"])
    np.testing.assert_array_equal(load_monte_carlo(out).values["y"], full.values["y"])
    # another study into the same directory is refused
    with pytest.raises(ConfigError, match="another study"):
        run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=20, chunk_size=5, seed=2, out_dir=str(out)))


def test_statistics_and_failures():
    def trial(seed: int, i: int) -> dict[str, float]:
        if i % 10 == 9:
            raise TooThinError("crescent too thin")
        return gaussian_trial(seed, i)

    res = run_monte_carlo(trial, MonteCarloOptions(n_trials=2000, chunk_size=500, seed=3, progress=False))
    assert res.failure_counts() == {"too_thin": 200}
    st = res.stats(truth={"x": 1.0}, crlb={"x": 0.5, "y": 1.0}, keys=["x", "y"])
    assert st["n_ok"] == 1800
    px = st["params"]["x"]
    assert px["rms"] == pytest.approx(0.5, rel=0.06)
    assert abs(px["bias"]) < 4 * px["bias_se"]
    assert px["rms_over_crlb"] == pytest.approx(1.0, rel=0.06)
    assert px["percentiles"]["50"] == pytest.approx(0.0, abs=0.05)
    assert st["params"]["y"]["percentiles"]["97.5"] == pytest.approx(1.96, abs=0.15)
    assert res.histogram("n_steps") == {3: 600, 4: 600, 5: 600}
    assert json.dumps(stats_json(res, truth={"x": 1.0}))
    with pytest.raises(LimbInputError, match="no trial returned"):
        res.stats(keys=["nope"])


def test_batched_trials_and_ok_flag(tmp_path):
    def batch(seeds: np.ndarray, idx: np.ndarray) -> dict[str, np.ndarray]:
        x = np.array([np.random.default_rng(int(s)).standard_normal() for s in seeds])
        return {"x": x, "ok": idx % 4 != 0}

    res = run_monte_carlo(batch, MonteCarloOptions(n_trials=40, chunk_size=16, batched=True, progress=False))
    single = run_monte_carlo(lambda s, i: {"x": np.random.default_rng(s).standard_normal()},
                             MonteCarloOptions(n_trials=40, chunk_size=7, progress=False))
    np.testing.assert_array_equal(res.values["x"], single.values["x"])
    assert res.ok.sum() == 30 and set(res.error[~res.ok]) == {"trial_failed"}
    with pytest.raises(LimbInputError, match="shape"):
        run_monte_carlo(lambda s, i: {"x": np.zeros(3)}, MonteCarloOptions(n_trials=4, batched=True, progress=False))


def test_plots(tmp_path):
    res = run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=300, chunk_size=300, progress=False))
    plot_errors(res, ["x", "y"], truth={"x": 1.0}, crlb={"x": 0.5, "y": 1.0}, path=tmp_path / "h.png")
    plot_rms_vs_crlb([{"crlb": 0.5, "rms": 0.51, "label": "x"}, {"crlb": 1.0, "rms": 0.98}], path=tmp_path / "r.png")
    assert (tmp_path / "h.png").stat().st_size > 5000 and (tmp_path / "r.png").stat().st_size > 5000


def test_options_validation():
    with pytest.raises(LimbInputError, match="n_trials"):
        MonteCarloOptions(n_trials=0)
    with pytest.raises(LimbInputError, match="chunk_size"):
        MonteCarloOptions(n_trials=3, chunk_size=0)


def test_two_processes_share_one_directory(tmp_path):
    out = str(tmp_path / "shared")
    kw = dict(n_trials=25, chunk_size=4, seed=9, out_dir=out, progress=False)
    a = run_monte_carlo(gaussian_trial, MonteCarloOptions(**kw, shard=(0, 2)))
    assert a.chunks_run == 4 and a.n == 13  # chunks 0, 2, 4 (4 trials each) and 6 (trial 24)
    b = run_monte_carlo(gaussian_trial, MonteCarloOptions(**kw, shard=(1, 2)))
    assert b.chunks_run == 3 and b.chunks_skipped == 4 and b.n == 25
    whole = run_monte_carlo(gaussian_trial, MonteCarloOptions(n_trials=25, chunk_size=4, seed=9, progress=False))
    np.testing.assert_array_equal(load_monte_carlo(out).values["x"], whole.values["x"])
    with pytest.raises(LimbInputError, match="shard"):
        MonteCarloOptions(n_trials=3, shard=(2, 2), out_dir=out)
