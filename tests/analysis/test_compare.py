"""Every solver on the same realisations (jaxlimb.analysis.compare) and the standard problems of every model."""

from __future__ import annotations

import numpy as np
import pytest

from jaxlimb.analysis.compare import CompareOptions, compare_solvers, compare_table, interleaved_timings, plot_compare
from jaxlimb.analysis.model_study import noisy_intensities, seeded_fits
from jaxlimb.analysis.problems import STUDY_MODELS, ModelStudyOptions, standard_problem
from jaxlimb.errors import LimbInputError
from jaxlimb.fitting import solver_from_name

LINEAR = ModelStudyOptions(model="linear", radius=20.0, shape=(60, 60))


def test_interleaved_timings_rotate_the_order_and_keep_the_first_repeat():
    calls, order = {}, []
    for name in ("a", "b", "c"):
        calls[name] = (lambda b, n=name: order.append((n, b)) or (n, b))
    times, out = interleaved_timings(calls, n_blocks=3, repeats=2)
    assert [o[0] for o in order[:6]] == ["a", "b", "c"] * 2  # block 0: a first
    assert [o[0] for o in order[6:9]] == ["b", "c", "a"]  # block 1 starts with the next solver
    assert all(len(t) == 6 for t in times.values())
    assert out["b"] == [("b", 0), ("b", 1), ("b", 2)]


def test_every_solver_fits_the_same_realisations():
    p = standard_problem(LINEAR)
    res = compare_solvers(p, CompareOptions(solvers=("lm", "paper", "scipy"), n=6, chunk=3))
    rows = {r["solver"]: r for r in res["rows"]}
    assert list(rows) == ["lm", "paper", "scipy"] and res["problem"]["model"] == "linear"
    for r in rows.values():
        assert r["success_rate"] == 1.0 and r["failures"] == {} and r["n_timings"] == 2
        assert r["max_abs_diff_vs_first_px"] < 1e-6  # the same data, the same minimum
        assert r["params"]["xt"]["rms"] == pytest.approx(rows["lm"]["params"]["xt"]["rms"], rel=1e-5)
    assert "RMS/CRLB xt" in compare_table(res)
    single = compare_solvers(p, CompareOptions(solvers=("lm", "paper"), n=6, chunk=3, mode="single"))
    for a, b in zip(res["rows"][:2], single["rows"]):  # one fit() per realisation: the same answers
        assert a["params"]["xt"]["rms"] == pytest.approx(b["params"]["xt"]["rms"], rel=1e-6)


def test_failures_are_counted_by_reason():
    """The paper's undamped iteration started far from a steep edge diverges (FitResult.diverged)."""
    from dataclasses import replace

    p = standard_problem(ModelStudyOptions(model="circle", radius=30.0, shape=(100, 100), k=3.0, annulus=10.0))
    far = replace(p, init=p.init.replace(r0=float(p.truth.r0) + 5.0, radius=float(p.truth.radius) + 6.0))
    res = compare_solvers(far, CompareOptions(solvers=("lm", "paper"), n=4, chunk=4))
    lm, paper = res["rows"]
    assert lm["success_rate"] == 1.0
    assert paper["success_rate"] < 1.0 and sum(paper["failures"].values()) == 4 - paper["n_ok"]
    assert set(paper["failures"]) <= {"diverged", "max_steps_reached"}


def test_plot_compare(tmp_path):
    res = compare_solvers(standard_problem(LINEAR), CompareOptions(solvers=("lm", "paper"), n=4, chunk=2))
    plot_compare(res, tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 1000


@pytest.mark.parametrize("kw, match", [({"solvers": ("lm", "nope")}, "solvers"), ({"solvers": ()}, "solvers"),
                                       ({"mode": "fast"}, "mode"), ({"n": 1}, "`n`"), ({"repeats": 0}, "repeats")])
def test_bad_options(kw, match):
    with pytest.raises(LimbInputError, match=match):
        CompareOptions(**kw)


@pytest.mark.parametrize("model", STUDY_MODELS)
def test_standard_problem_of_every_model(model):
    """Truth, start and pixels: the start is off in the centre (or the edge) by ``start_offset_px``, the pixels a
    band around the limb, the held parameters the model's own."""
    opt = ModelStudyOptions(model=model, radius=40.0, shape=(120, 120))
    p = standard_problem(opt)
    assert p.model.name in ("linear", "circle", "ellipse", "ellipse_ramp", "lunar_limb", "limb_darkened")
    assert p.coords.shape[0] > 200 and np.all(np.isfinite(p.clean))
    assert set(p.free) and not set(p.free) & set(p.fixed)
    t, s = np.asarray(p.truth.to_vector()), np.asarray(p.init.to_vector())
    moved = {n for n, a, b in zip(p.model.param_names, t, s) if a != b}
    assert moved and moved <= set(p.free)
    if model != "linear":
        assert np.hypot(s[0] - t[0], s[1] - t[1]) == pytest.approx(opt.start_offset_px)


def test_noise_is_drawn_per_seed_and_per_pixel_sigma():
    p = standard_problem(LINEAR)
    z = noisy_intensities(np.array([3, 4]), p.clean, p.noise_scale)
    again = noisy_intensities(np.array([4]), p.clean, p.noise_scale)
    np.testing.assert_allclose(z[1], again[0], rtol=1e-13)  # (batch size changes the vectorised rounding)
    assert np.std(z[0] - p.clean) == pytest.approx(p.sigma, rel=0.1)


def test_seeded_fits_draw_the_same_noise_as_noisy_intensities():
    """The compiled program's realisations are those of :func:`noisy_intensities`: a fit of the drawn data agrees."""
    from jaxlimb.fitting import fit

    p = standard_problem(LINEAR)
    seeds = np.array([11, 12], dtype=np.int64)
    out = seeded_fits(p, solver_from_name("lm"), 2)(seeds)
    z = noisy_intensities(seeds, p.clean, p.noise_scale)
    ref = fit(p.model, p.coords, z[1], p.init, fixed=p.fixed)
    assert out["params"][1][0] == pytest.approx(float(ref.params.xt), abs=1e-7)
