"""optimistix solvers with the fused analytic Jacobian and the normal-equations solve."""

import lineax as lx
import numpy as np
import optimistix as optx
import pytest

from jaxlimb.fitting import NormalLM, Optimistix, fit
from jaxlimb.fitting.solvers import OPTX_ATOL, OPTX_RTOL, solver_from_name
from jaxlimb.models import CIRCLE, ELLIPSE

from .helpers import circle_problem, ellipse_problem


@pytest.mark.parametrize("make", [lambda: optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10),
                                  lambda: optx.Dogleg(rtol=1e-10, atol=1e-10)])
def test_fused_normal_optimistix_gives_the_same_answer(make):
    coords, z, truth = circle_problem(radius=60.0, shape=(160, 160), seed=3)
    init = truth.replace(r0=truth.r0 + 0.4, radius=truth.radius - 0.4, k=2.5, ymax=180.0)
    ref = fit(CIRCLE, coords, z, init, NormalLM())
    fast = fit(CIRCLE, coords, z, init, Optimistix(make(), coarse_stride=1))
    plain = fit(CIRCLE, coords, z, init, Optimistix(make(), fused=False, normal=False, coarse_stride=1))
    a, b, c = (np.asarray(r.params.to_vector()) for r in (ref, fast, plain))
    np.testing.assert_allclose(b, a, atol=1e-7)
    np.testing.assert_allclose(c, a, atol=1e-7)
    # the same algorithm: the same steps up to rounding near convergence
    assert abs(int(fast.n_steps) - int(plain.n_steps)) <= 0.2 * int(plain.n_steps) + 1


def test_normal_swaps_only_the_linear_solver():
    s = Optimistix(optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8))
    conf = s.configured()
    assert isinstance(conf.descent.linear_solver, lx.Normal)
    assert conf.rtol == 1e-8 and type(conf) is optx.LevenbergMarquardt
    assert Optimistix(optx.BFGS(rtol=1e-8, atol=1e-8)).configured() is not None  # no descent.linear_solver: as is
    assert isinstance(Optimistix(optx.Dogleg(rtol=1e-8, atol=1e-8), normal=False).configured().descent.linear_solver,
                      lx.AutoLinearSolver)


def test_fused_residual_on_the_ellipse_with_fixed_parameters():
    coords, z, truth = ellipse_problem(a=60.0, shape=(300, 300), seed=1)
    init = truth.replace(a=truth.a + 0.5, theta=truth.theta + 0.02)
    fixed = ("rho", "k")
    ref = fit(ELLIPSE, coords, z, init, NormalLM(), fixed=fixed)
    fast = fit(ELLIPSE, coords, z, init, Optimistix(optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)), fixed=fixed)
    np.testing.assert_allclose(np.asarray(fast.params.to_vector()), np.asarray(ref.params.to_vector()), atol=1e-6)


@pytest.mark.parametrize("make", [lambda: optx.LevenbergMarquardt(rtol=OPTX_RTOL, atol=OPTX_ATOL),
                                  lambda: optx.Dogleg(rtol=OPTX_RTOL, atol=OPTX_ATOL)])
def test_coarse_phase_changes_the_cost_not_the_answer(make):
    coords, z, truth = circle_problem(radius=150.0, shape=(400, 400), seed=5)
    assert len(z) >= 4 * 1024  # the coarse phase runs on every 4th of >= 1024 pixels
    init = truth.replace(r0=truth.r0 + 0.35, c0=truth.c0 - 0.35, radius=truth.radius + 0.5, k=2.5, ymax=180.0)
    ref = fit(CIRCLE, coords, z, init, NormalLM())
    coarse = fit(CIRCLE, coords, z, init, Optimistix(make()))
    fine = fit(CIRCLE, coords, z, init, Optimistix(make(), coarse_stride=1))
    assert coarse.converged and fine.converged
    a, b, c = (np.asarray(r.params.to_vector()) for r in (ref, coarse, fine))
    np.testing.assert_allclose(b, a, atol=1e-6)
    np.testing.assert_allclose(c, a, atol=1e-6)


def test_optimistix_own_stopping_test_reaches_the_same_minimum_in_more_steps():
    """optimistix's Cauchy test at 1e-10 (every pixel's residual change, one more accepted step) vs StepStop:
    the same minimum, no fewer steps for the former."""
    coords, z, truth = circle_problem(radius=60.0, shape=(160, 160), seed=3)
    init = truth.replace(r0=truth.r0 + 0.4, k=2.5)
    lm = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)
    own = fit(CIRCLE, coords, z, init, Optimistix(lm, step_stop=False))
    ours = fit(CIRCLE, coords, z, init, Optimistix(lm))
    assert own.converged and ours.converged and int(ours.n_steps) <= int(own.n_steps)
    np.testing.assert_allclose(np.asarray(ours.params.to_vector()), np.asarray(own.params.to_vector()), atol=1e-6)


def test_the_registry_runs_optimistix_lm_and_dogleg_configured_not_replaced():
    for name, cls in (("optx-lm", optx.LevenbergMarquardt), ("dogleg", optx.Dogleg)):
        s = solver_from_name(name)
        assert type(s.solver) is cls and s.name == cls.__name__  # optimistix's algorithm: its descent and search
        assert s.step_stop and (s.solver.rtol, s.solver.atol) == (NormalLM.rtol, NormalLM.atol)  # the default's rule


def test_the_step_count_tail_of_optimistix_lm_and_dogleg_is_the_defaults():
    """A vmapped batch runs until its slowest fit stops: the tail of the step counts is the cost."""
    steps, params = {}, {}
    for name in ("lm", "optx-lm", "dogleg"):
        solver = solver_from_name(name)
        fits = []
        for seed in range(6):
            coords, z, truth = circle_problem(seed=seed)
            init = truth.replace(r0=truth.r0 + 0.35, c0=truth.c0 - 0.35, radius=truth.radius + 0.5)
            fits.append(fit(CIRCLE, coords, z, init, solver))
        steps[name] = np.array([int(f.n_steps) for f in fits])
        params[name] = np.array([np.asarray(f.params.to_vector())[:3] for f in fits])
    for name in ("optx-lm", "dogleg"):
        assert steps[name].max() <= steps["lm"].max() + 3, (name, steps)
        np.testing.assert_allclose(params[name], params["lm"], atol=1e-6)


def test_optimistix_results_keep_their_names_as_fit_results():
    from jaxlimb.fitting import FitResult

    coords, z, truth = circle_problem(radius=60.0, shape=(160, 160), seed=3)
    init = truth.replace(r0=truth.r0 + 0.4, k=2.5)
    res = fit(CIRCLE, coords, z, init, Optimistix(optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)), max_steps=2,
              throw=False)
    assert not bool(res.converged)
    assert bool(res.result == FitResult.nonlinear_max_steps_reached)
    assert "maximum number of steps" in res.message


def test_the_default_path_does_not_import_optimistix():
    import subprocess
    import sys

    code = ("import sys, numpy as np; from jaxlimb.fitting import fit, NormalLM; from jaxlimb.models import CIRCLE, "
            "CircleParams; rr, cc = np.mgrid[0:80, 0:80]; c = np.stack([rr.ravel(), cc.ravel()], -1).astype(float); "
            "t = CircleParams(40.2, 39.7, 25.0, 2.0, 200.0, 20.0); z = np.asarray(CIRCLE.intensity(t, c)); "
            "r = fit(CIRCLE, c, z, t.replace(r0=40.5), NormalLM()); "
            "print(bool(r.converged), 'optimistix' in sys.modules, 'lineax' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "False", "False"]


def test_scaled_bfgs_reaches_the_same_minimum_as_optimistix_bfgs_in_fewer_steps():
    """BFGS started from I/|g0| (the registered ``bfgs``) vs optimistix's identity start: only the start's scale
    differs, the minimum is the same (the default's to 1e-7 px) and the Armijo search stops halving its first steps."""
    from jaxlimb.fitting.solvers import ScaledBFGS

    coords, z, truth = circle_problem(radius=60.0, shape=(160, 160), seed=3)
    init = truth.replace(r0=truth.r0 + 0.4, k=2.5)
    ref = fit(CIRCLE, coords, z, init, NormalLM())
    identity = fit(CIRCLE, coords, z, init, Optimistix(optx.BFGS(rtol=OPTX_RTOL, atol=OPTX_ATOL), coarse_stride=1))
    scaled = fit(CIRCLE, coords, z, init, Optimistix(ScaledBFGS(rtol=OPTX_RTOL, atol=OPTX_ATOL), coarse_stride=1))
    assert identity.converged and scaled.converged and 2 * int(scaled.n_steps) < int(identity.n_steps)
    for res in (identity, scaled):
        np.testing.assert_allclose(np.asarray(res.params.to_vector())[:3], np.asarray(ref.params.to_vector())[:3],
                                   atol=1e-7)
    assert type(solver_from_name("bfgs").solver) is ScaledBFGS
