"""The fitting interface: accuracy, agreement with SciPy, fixed parameters, failures, batching."""

import os
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxlimb.errors import ConvergenceError, LimbInputError
from jaxlimb.fitting import (
    FitResult,
    NormalLM,
    Optimistix,
    PaperGaussNewton,
    ScipyLeastSquares,
    bucket_size,
    compile_count,
    fit,
    fit_batch,
    optimistix_normal_lm,
    pack_pixels,
    solver_from_name,
)
from jaxlimb.models import CIRCLE, ELLIPSE, LINEAR, CircleParams, LinearParams
from jaxlimb.fitting.solvers import OPTX_ATOL, OPTX_RTOL

from .helpers import circle_problem, ellipse_problem

SOLVERS = {
    "lm": NormalLM(),
    "optx-normal-lm": optimistix_normal_lm(),
    "optx-lm": Optimistix(optx.LevenbergMarquardt(rtol=OPTX_RTOL, atol=OPTX_ATOL)),
    "dogleg": Optimistix(optx.Dogleg(rtol=OPTX_RTOL, atol=OPTX_ATOL)),
    "gauss-newton": Optimistix(optx.GaussNewton(rtol=OPTX_RTOL, atol=OPTX_ATOL)),
    "bfgs": Optimistix(optx.BFGS(rtol=1e-12, atol=1e-12)),
    "paper": PaperGaussNewton(),
    "scipy": ScipyLeastSquares(),
}


@pytest.fixture(scope="module")
def circ():
    return circle_problem(sigma=10.0, seed=1)


@pytest.fixture(scope="module")
def scipy_reference(circ):
    coords, z, truth = circ
    init = truth.replace(r0=truth.r0 + 0.4, c0=truth.c0 - 0.3, radius=truth.radius + 0.5, k=2.5, ymax=190.0, ymin=25.0)
    return init, fit(CIRCLE, coords, z, init, ScipyLeastSquares())


@pytest.mark.parametrize("name", list(SOLVERS))
def test_every_solver_agrees_with_scipy_to_1e6_px(name, circ, scipy_reference):
    coords, z, truth = circ
    init, ref = scipy_reference
    res = fit(CIRCLE, coords, z, init, SOLVERS[name])
    assert bool(res.converged)
    tol = 1e-5 if name == "bfgs" else 1e-6  # BFGS has no Gauss-Newton curvature: looser endgame
    for p in ("r0", "c0", "radius"):
        assert abs(float(getattr(res.params, p)) - float(getattr(ref.params, p))) <= tol, (name, p)
    # and the estimate is where the noise puts it: within 5 sigma of the truth
    for p in ("r0", "c0", "radius"):
        assert abs(float(getattr(res.params, p)) - float(getattr(truth, p))) < 5 * float(res.std[p])


def test_covariance_is_sigma2_inverse_normal_matrix(circ):
    coords, z, truth = circ
    res = fit(CIRCLE, coords, z, truth)
    jac = np.asarray(CIRCLE.jacobian(res.params, jnp.asarray(coords)))
    r = np.asarray(CIRCLE.intensity(res.params, jnp.asarray(coords))) - z
    s2 = r @ r / (len(z) - 6)
    np.testing.assert_allclose(float(res.sigma2), s2, rtol=1e-10)
    np.testing.assert_allclose(np.asarray(res.covariance), s2 * np.linalg.inv(jac.T @ jac), rtol=1e-8)
    np.testing.assert_allclose(float(res.rms), np.sqrt(r @ r / len(z)), rtol=1e-10)
    assert abs(float(res.sigma2) ** 0.5 - 10.0) < 0.3  # the noise we put in
    assert int(res.n_pixels) == len(z)


def test_table1_fixed_k_ymax_ymin_gives_3_parameter_fit(circ):
    coords, z, truth = circ
    init = truth.replace(r0=truth.r0 + 1.0, radius=truth.radius - 1.0)
    res = fit(CIRCLE, coords, z, init, PaperGaussNewton(), fixed=("k", "ymax", "ymin"))
    assert res.free == ("r0", "c0", "radius")
    assert np.asarray(res.covariance).shape == (3, 3)
    assert float(res.params.k) == 3.0 and float(res.params.ymax) == 200.0
    assert abs(float(res.params.radius) - 150.0) < 0.02


def test_ellipse_fit_rho_fixed():
    coords, z, truth = ellipse_problem()
    init = truth.replace(r0=truth.r0 + 0.5, c0=truth.c0 - 0.5, a=truth.a + 0.7, theta=truth.theta + 0.02, k=2.0)
    res = fit(ELLIPSE, coords, z, init, fixed=("rho",))
    assert "rho" not in res.free
    for p in ("r0", "c0", "a"):
        assert abs(float(getattr(res.params, p)) - float(getattr(truth, p))) < 5 * float(res.std[p])
    assert abs(float(res.params.theta) - 0.4) < 5 * float(res.std["theta"])


def test_linear_fit_recovers_transition():
    x = np.linspace(0, 100, 201)
    truth = LinearParams(50.0, 0.9, 150.0, 20.0)
    z = np.asarray(LINEAR.intensity(truth, jnp.asarray(x)))
    res = fit(LINEAR, x, z, LinearParams(47.0, 0.5, 140.0, 30.0))
    np.testing.assert_allclose(np.asarray(res.params.to_vector()), np.asarray(truth.to_vector()), atol=1e-8)


@settings(max_examples=8, deadline=None)
@given(radius=st.floats(5.0, 500.0), dr=st.floats(-1.0, 1.0), dc=st.floats(-1.0, 1.0))
def test_recovers_truth_for_any_radius(radius, dr, dc):
    """Noise-free data: the default solver recovers any radius in [5, 500] px to 1e-6 px."""
    shape = (int(2 * radius + 40),) * 2
    coords, z, truth = circle_problem(radius=radius, sigma=0.0, shape=shape)
    init = truth.replace(r0=truth.r0 + dr, c0=truth.c0 + dc, radius=radius * 1.01, k=2.0)
    res = fit(CIRCLE, coords, z, init)
    for p in ("r0", "c0", "radius"):
        assert abs(float(getattr(res.params, p)) - float(getattr(truth, p))) < 1e-6


def test_undamped_gauss_newton_diverges_and_is_not_reported_as_success():
    """From 5 px / 5 % off with k = 3 the paper's undamped iteration leaves the basin; LM does not."""
    coords, z, truth = circle_problem(sigma=10.0, seed=2)
    init = truth.replace(r0=truth.r0 + 4.0, c0=truth.c0 - 3.0, radius=truth.radius * 1.05)
    bad = fit(CIRCLE, coords, z, init, PaperGaussNewton(), throw=False)
    good = fit(CIRCLE, coords, z, init, NormalLM())
    assert abs(float(good.params.radius) - 150.0) < 0.02
    if bool(bad.converged):  # if it "converged", it must be to the right answer
        assert abs(float(bad.params.radius) - 150.0) < 0.02
    else:
        with pytest.raises(ConvergenceError, match="did not converge"):
            fit(CIRCLE, coords, z, init, PaperGaussNewton())


def test_max_steps_is_a_failure_not_a_success(circ):
    coords, z, truth = circ
    init = truth.replace(r0=truth.r0 + 1.0)
    res = fit(CIRCLE, coords, z, init, NormalLM(), max_steps=1, throw=False)
    assert not bool(res.converged)
    assert res.result == FitResult.max_steps_reached
    with pytest.raises(ConvergenceError, match="maximum number"):
        fit(CIRCLE, coords, z, init, NormalLM(), max_steps=1)


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda c, z, p: (c, np.where(np.arange(len(z)) == 3, np.nan, z), p), r"`z` has a non-finite value nan at index \(3,\)"),
        (lambda c, z, p: (c[:0], z[:0], p), "empty"),
        (lambda c, z, p: (c[:5], z[:5], p), "more pixels than free parameters"),
        (lambda c, z, p: (c, z, p.replace(radius=-3.0)), r"`init.radius` must be > 0, got -3.0"),
        (lambda c, z, p: (c, z, p.replace(k=0.0)), r"`init.k` must be > 0"),
        (lambda c, z, p: (c, z[:-1], p), r"`z` must have shape"),
        (lambda c, z, p: (c[:, :1], z, p), r"`coords` must have shape"),
        (lambda c, z, p: (c, z, LinearParams(0.0, 1.0, 1.0, 0.0)), "must be a CircleParams"),
    ],
)
def test_bad_input_raises_typed_error_naming_argument(circ, mutate, match):
    coords, z, truth = circ
    c, zz, p = mutate(coords, z, truth)
    with pytest.raises(LimbInputError, match=match):
        fit(CIRCLE, c, zz, p)


def test_unknown_fixed_name_and_solver_name():
    coords, z, truth = circle_problem(sigma=1.0, radius=20.0, shape=(60, 60))
    with pytest.raises(LimbInputError, match="unknown parameters"):
        fit(CIRCLE, coords, z, truth, fixed=("kappa",))
    with pytest.raises(LimbInputError, match="`solver` must be one of"):
        solver_from_name("newton-raphson")


def test_bucket_sizes_are_monotone_and_bounded():
    sizes = [bucket_size(n) for n in range(1, 100_000, 37)]
    assert all(b >= n for b, n in zip(sizes, range(1, 100_000, 37)))
    assert all(b <= max(256, 1.5 * n) + 1 for b, n in zip(sizes, range(1, 100_000, 37)))
    assert len(set(sizes)) < 30


@pytest.mark.parametrize("strategy", ["map", "vmap"])
def test_batch_matches_single_fits_and_never_recompiles(strategy):
    """Different pixel counts in one bucket, padded with masks: same answers, no NaN, one compilation."""
    probs = [circle_problem(radius=r, sigma=5.0, seed=i, shape=(160, 160)) for i, r in enumerate((60.0, 61.5, 62.0))]
    coords, z, w = pack_pixels([p[0] for p in probs], [p[1] for p in probs])
    assert len({len(p[1]) for p in probs}) == 3 and coords.shape[1] == bucket_size(max(len(p[1]) for p in probs))
    inits = [p[2].replace(r0=p[2].r0 + 0.3, radius=p[2].radius - 0.4) for p in probs]
    init = CircleParams.from_vector(jnp.stack([i.to_vector() for i in inits]))
    res = fit_batch(CIRCLE, coords, z, init, weights=w, strategy=strategy)
    assert np.all(np.asarray(res.converged))
    assert np.all(np.isfinite(np.asarray(res.covariance)))
    for i, (c, zi, _) in enumerate(probs):
        single = fit(CIRCLE, c, zi, inits[i])
        np.testing.assert_allclose(np.asarray(res.params.to_vector())[i], np.asarray(single.params.to_vector()), atol=1e-8)
        assert int(res.n_pixels[i]) == len(zi)
    before = compile_count()
    rng = np.random.default_rng(5)
    for _ in range(3):
        res2 = fit_batch(CIRCLE, coords, z + rng.normal(0, 1, z.shape) * w, init, weights=w, strategy=strategy)
    assert compile_count() == before, "same bucket, same batch size: must not recompile"
    assert np.all(np.asarray(res2.converged))


def test_single_fits_in_one_bucket_compile_once():
    a = circle_problem(radius=60.0, sigma=5.0, shape=(160, 160))
    b = circle_problem(radius=61.0, sigma=5.0, seed=3, shape=(160, 160))
    assert bucket_size(len(a[1])) == bucket_size(len(b[1]))
    fit(CIRCLE, a[0], a[1], a[2])
    before = compile_count()
    fit(CIRCLE, b[0], b[1], b[2])
    fit(CIRCLE, a[0], a[1] + 1.0, a[2])
    assert compile_count() == before


def test_held_by_mask_equals_fixed_and_shares_one_program():
    """``held`` (a run-time mask) gives the fit with those parameters fixed, and every held set and step
    limit runs one compiled program."""
    coords, z, truth = circle_problem(radius=60.0, sigma=5.0, shape=(160, 160), seed=7)
    init = truth.replace(r0=truth.r0 + 0.4, c0=truth.c0 - 0.3, radius=truth.radius + 0.5, k=2.5)
    free = fit(CIRCLE, coords, z, init, fixed=("ymin",), held=(), max_steps=50)
    for hold, steps in ((("k",), 64), (("k", "ymax"), 80), ((), 40)):
        before = compile_count()
        masked = fit(CIRCLE, coords, z, init, fixed=("ymin",), held=hold, max_steps=steps)
        assert compile_count() == before, f"held={hold}, max_steps={steps}: a second program"
        static = fit(CIRCLE, coords, z, init, fixed=("ymin", *hold), max_steps=steps)
        assert masked.free == static.free and int(masked.n_steps) == int(static.n_steps)
        np.testing.assert_allclose(np.asarray(masked.params.to_vector()), np.asarray(static.params.to_vector()),
                                   rtol=0, atol=1e-10)
        np.testing.assert_allclose(np.asarray(masked.covariance), np.asarray(static.covariance), rtol=1e-9)
        np.testing.assert_allclose(float(masked.sigma2), float(static.sigma2), rtol=1e-12)
        for name in hold:
            assert float(getattr(masked.params, name)) == float(getattr(init, name))
    np.testing.assert_allclose(np.asarray(free.params.to_vector()),
                               np.asarray(fit(CIRCLE, coords, z, init, fixed=("ymin",), max_steps=50).params.to_vector()),
                               atol=1e-10)
    paper = fit(CIRCLE, coords, z, init, PaperGaussNewton(), fixed=("ymin",), held=("k",))  # no mask: held -> fixed
    assert paper.free == ("r0", "c0", "radius", "ymax") and float(paper.params.k) == float(init.k)
    with pytest.raises(LimbInputError, match="not free"):
        fit(CIRCLE, coords, z, init, fixed=("ymin",), held=("ymin",))
    with pytest.raises(LimbInputError, match="every free"):
        fit(CIRCLE, coords, z, init, fixed=("ymin",), held=("r0", "c0", "radius", "k", "ymax"))


def test_float32_warns():
    code = (
        "import warnings, numpy as np\n"
        "from jaxlimb.fitting import fit, PrecisionWarning\n"
        "from jaxlimb.models import CIRCLE, CircleParams\n"
        "rr, cc = np.mgrid[0:40, 0:40]; c = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)\n"
        "p = CircleParams(20.0, 20.0, 10.0, 2.0, 100.0, 0.0)\n"
        "z = np.asarray(CIRCLE.intensity(p, c))\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    fit(CIRCLE, c, z, p, throw=False)\n"
        "print(any(issubclass(x.category, PrecisionWarning) for x in w))\n"
    )
    env = {**os.environ, "JAX_ENABLE_X64": "0"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.stdout.strip().endswith("True"), out.stderr
