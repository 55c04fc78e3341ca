"""optimistix solvers with the fused analytic Jacobian and the normal-equations solve."""

import lineax as lx
import numpy as np
import optimistix as optx
import pytest

from jaxlimb.fitting import NormalLM, Optimistix, fit
from jaxlimb.fitting.solvers import OPTX_ATOL, OPTX_RTOL
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


def test_tolerance_at_the_rounding_floor_still_converges_to_the_same_answer():
    """atol = 1e-10 DN per pixel: more steps (OPTX_ATOL's note), the same minimum."""
    coords, z, truth = circle_problem(radius=60.0, shape=(160, 160), seed=3)
    init = truth.replace(r0=truth.r0 + 0.4, k=2.5)
    tight = fit(CIRCLE, coords, z, init, Optimistix(optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)))
    loose = fit(CIRCLE, coords, z, init, Optimistix(optx.LevenbergMarquardt(rtol=OPTX_RTOL, atol=OPTX_ATOL)))
    assert int(loose.n_steps) <= int(tight.n_steps)
    np.testing.assert_allclose(np.asarray(loose.params.to_vector()), np.asarray(tight.params.to_vector()), atol=1e-6)


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
