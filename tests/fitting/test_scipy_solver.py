"""The SciPy baseline (jaxlimb.fitting.scipy_solver): one compiled call per point, MINPACK's answers unchanged."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.optimize import least_squares

from jaxlimb.fitting import LimbProblem, ScipyLeastSquares, fit
from jaxlimb.fitting.scipy_solver import HostResidual, scipy_callables
from jaxlimb.models import CIRCLE, CircleParams


@pytest.fixture(scope="module")
def circle_problem():
    rc = np.argwhere(np.ones((48, 48))).astype(float)
    d = np.hypot(rc[:, 0] - 23.3, rc[:, 1] - 22.6)
    z = 10.0 + 190.0 / (1.0 + np.exp(2.0 * (d - 15.0))) + np.random.default_rng(3).normal(0.0, 4.0, len(d))
    init = CircleParams(r0=24.0, c0=24.0, radius=14.0, k=1.5, ymax=180.0, ymin=20.0)
    return rc, z, init


def test_scipy_answers_equal_least_squares_on_separate_residual_and_jacobian(circle_problem):
    """The fused host path gives what SciPy gives on the residual and the model's Jacobian called apart."""
    rc, z, init = circle_problem
    res = fit(CIRCLE, rc, z, init, ScipyLeastSquares(), throw=False)
    free = tuple(range(6))
    p = LimbProblem(CIRCLE, free, True, *(jax.numpy.asarray(a) for a in (init.to_vector(), rc, z, np.ones(len(z)))))
    resid, jac = jax.jit(p.residual), jax.jit(lambda y, args: LimbProblem(CIRCLE, free, True, *args).jacobian(y))
    ref = least_squares(lambda y: np.asarray(resid(y, p.args)), np.asarray(init.to_vector()),
                        jac=lambda y: np.asarray(jac(y, p.args)), method="lm", x_scale="jac",
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    assert bool(res.converged) and ref.status > 0
    np.testing.assert_allclose(np.asarray(res.params.to_vector())[:3], ref.x[:3], rtol=0, atol=1e-9)  # px
    assert int(res.n_steps) == ref.njev


def test_host_residual_makes_one_call_per_point(circle_problem):
    rc, z, init = circle_problem
    p = LimbProblem(CIRCLE, tuple(range(6)), True, *(jax.numpy.asarray(a) for a in (init.to_vector(), rc, z,
                                                                                    np.ones(len(z)))))
    parts, _ = scipy_callables(p)
    calls = []
    host = HostResidual(lambda y, args: calls.append(y) or parts(y, args), p.args)
    y = np.asarray(init.to_vector())
    r, jac = host.residual(y), host.jacobian(y)
    assert len(calls) == 1 and r.shape == (len(z),) and jac.shape == (len(z), 6) and jac.flags.f_contiguous
    host.residual(y + 1e-3), host.jacobian(y), host.jacobian(y + 1e-3)  # the last two points are kept
    assert len(calls) == 2
