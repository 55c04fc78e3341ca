"""Sigmoid models: values, the paper's Jacobians vs autodiff / central differences, the ESF transform."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxlimb.models import (
    CIRCLE,
    ELLIPSE,
    LINEAR,
    CircleParams,
    EllipseParams,
    LinearParams,
    circle_intensity,
    ellipse_coords,
    ellipse_intensity,
    ellipse_points,
    linear_intensity,
    linear_intensity_jac,
)
from jaxlimb.models.gradcheck import check_model, report


@pytest.mark.parametrize("model", [LINEAR, CIRCLE, ELLIPSE], ids=lambda m: m.name)
def test_paper_jacobian_matches_autodiff_and_fd(model):
    checks = check_model(model, n_points=100, seed=7)
    assert {c.param for c in checks} == set(model.param_names)
    for c in checks:
        assert c.n_points == 100
        assert c.max_rel_err <= 1e-9, c
        assert c.max_fd_err <= 1e-6, c


def test_gradcheck_report_shape():
    # every model is in the run (the CLI test runs them all: tests/cli/test_core_cli.py)
    rep = report(check_model(CIRCLE, n_points=3, seed=1))
    assert len(rep["checks"]) == 6
    assert set(rep["checks"][0]) >= {"model", "param", "max_rel_err", "n_points", "tol", "passed"}
    assert all(c["passed"] for c in rep["checks"])


def test_gradcheck_would_catch_a_wrong_formula():
    """A sign error in one column must show up as an O(1) relative error."""
    from jaxlimb.models import LimbModel

    bad_jac = lambda p, x: linear_intensity_jac(p, x).at[:, 1].multiply(-1.0)  # noqa: E731
    bad = LimbModel("linear", LinearParams, linear_intensity, bad_jac, LINEAR.jacobian_columns)
    assert check_model(LINEAR, n_points=5)[1].max_rel_err < 1e-12
    errs = {c.param: c.max_rel_err for c in check_model(bad, n_points=5)}
    assert errs["k"] > 1.0 and errs["xt"] < 1e-12


def test_linear_paper_identities():
    """Eq. 14's alternate forms: dymax = alpha*dymin, dxt = -dymin*dymax*(ymin-ymax)*k, dk = (xt-x)/k*dxt."""
    p = LinearParams(50.0, 0.4, 150.0, 20.0)
    x = jnp.linspace(0, 100, 41)
    j = np.asarray(linear_intensity_jac(p, x))
    alpha = np.exp(0.4 * (50.0 - np.asarray(x)))
    d_xt, d_k, d_ymax, d_ymin = j.T
    np.testing.assert_allclose(d_ymax, alpha * d_ymin, rtol=1e-12)
    np.testing.assert_allclose(d_xt, -d_ymin * d_ymax * (20.0 - 150.0) * 0.4, rtol=1e-12)
    np.testing.assert_allclose(d_k, (50.0 - np.asarray(x)) / 0.4 * d_xt, rtol=1e-10, atol=1e-14)


def test_levels_and_midpoint():
    p = CircleParams(10.0, 20.0, 5.0, 3.0, 200.0, 20.0)
    f = circle_intensity(p, jnp.array([[10.0, 20.0], [10.0, 25.0], [10.0, 45.0]]))
    np.testing.assert_allclose(f, [200.0 - 180.0 / (1 + np.exp(15.0)), 110.0, 20.0], rtol=1e-13, atol=1e-12)
    lp = LinearParams(50.0, 0.9, 150.0, 20.0)
    np.testing.assert_allclose(linear_intensity(lp, jnp.array([50.0])), [85.0])


def test_no_nan_for_steep_sigmoid_or_pixel_at_center():
    p = CircleParams(10.0, 20.0, 5.0, 500.0, 200.0, 20.0)
    rc = jnp.array([[10.0, 20.0], [10.0, 1000.0], [10.0, 25.0]])
    assert np.all(np.isfinite(CIRCLE.jacobian(p, rc)))
    assert np.all(np.isfinite(jax.jacfwd(lambda v: circle_intensity(CircleParams.from_vector(v), rc))(p.to_vector())))


@settings(max_examples=40, deadline=None)
@given(
    a=st.floats(5, 500),
    rho=st.floats(0.3, 1.0),
    theta=st.floats(-np.pi, np.pi),
    phi=st.floats(0, 2 * np.pi),
)
def test_ellipse_transform_roundtrip_and_level_set(a, rho, theta, phi):
    """Points of ellipse_points (Eq. 20) map back to beta = rho*a (Eq. 18) and f = (ymax+ymin)/2."""
    p = EllipseParams(300.0, 400.0, a, theta, rho, 2.0, 180.0, 10.0)
    rc = ellipse_points(p, jnp.array([phi]))
    x, y = ellipse_coords(p, rc)
    np.testing.assert_allclose(x, a * np.cos(phi), atol=1e-9 * a)
    np.testing.assert_allclose(y, rho * a * np.sin(phi), atol=1e-9 * a)
    np.testing.assert_allclose(ellipse_intensity(p, rc), 95.0, atol=1e-8)


def test_ellipse_reduces_to_circle():
    rng = np.random.default_rng(3)
    rc = jnp.asarray(rng.uniform(0, 200, (50, 2)))
    e = EllipseParams(100.0, 90.0, 60.0, 0.7, 1.0, 2.0, 180.0, 10.0)
    c = CircleParams(100.0, 90.0, 60.0, 2.0, 180.0, 10.0)
    np.testing.assert_allclose(ellipse_intensity(e, rc), circle_intensity(c, rc), rtol=1e-13)


def test_ellipse_theta_orientation():
    """theta turns the a-axis counter-clockwise on the displayed image (row down): theta=pi/2 -> a along -row."""
    p = EllipseParams(0.0, 0.0, 10.0, np.pi / 2, 0.5, 2.0, 1.0, 0.0)
    pts = np.asarray(ellipse_points(p, jnp.array([0.0, np.pi / 2])))
    np.testing.assert_allclose(pts[0], [-10.0, 0.0], atol=1e-12)  # end of a: up on the image
    np.testing.assert_allclose(pts[1], [0.0, -5.0], atol=1e-12)  # end of b: left


def test_params_vector_roundtrip_and_replace():
    p = EllipseParams(1.0, 2.0, 3.0, 0.1, 0.9, 2.0, 5.0, 1.0)
    q = EllipseParams.from_vector(p.to_vector())
    assert q.as_dict() == p.as_dict()
    assert p.replace(a=7.0).a == 7.0
    with pytest.raises(TypeError, match="no fields"):
        p.replace(radius=1.0)
