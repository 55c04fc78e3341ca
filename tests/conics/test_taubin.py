"""Taubin circle fit (Eq. 26-35), direct ellipse fit and geometric residuals."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxlimb.conics import (
    DegenerateFitError,
    circle_from_three,
    circle_residuals,
    ellipse_residuals,
    fit_circle_taubin,
    fit_ellipse_direct,
    taubin_circle_coefficients,
)
from jaxlimb.errors import LimbInputError


def arc(center, r, t0, t1, n):
    t = np.linspace(t0, t1, n)
    return np.c_[center[0] + r * np.sin(t), center[1] + r * np.cos(t)]


@pytest.mark.parametrize(
    "center, r, span",
    [((123.4, -55.5), 87.65, 2.0), ((1000.3, 1400.7), 300.0, 6.0), ((-400.0, 2000.0), 612.8, 0.6), ((0.0, 0.0), 2.5, 3.0)],
)
def test_taubin_exact_circle_to_1e9(center, r, span):
    f = fit_circle_taubin(arc(center, r, 0.3, 0.3 + span, 40))
    assert abs(f.center_rc[0] - center[0]) < 1e-9
    assert abs(f.center_rc[1] - center[1]) < 1e-9
    assert abs(f.radius - r) < 1e-9
    assert f.rms < 1e-9 and f.max_abs < 1e-9 and f.n == 40


@settings(max_examples=40, deadline=None)
@given(
    cr=st.floats(-2000, 2000),
    cc=st.floats(-2000, 2000),
    r=st.floats(5, 3000),
    t0=st.floats(0, 2 * math.pi),
    span=st.floats(0.5, 2 * math.pi),
)
def test_taubin_exact_circle_property(cr, cc, r, t0, span):
    f = fit_circle_taubin(arc((cr, cc), r, t0, t0 + span, 25))
    tol = 1e-9 * max(1.0, r / 100.0) * (1 + 3.0 / span**2)
    assert abs(f.radius - r) < tol * 10
    assert math.hypot(f.center_rc[0] - cr, f.center_rc[1] - cc) < tol * 10


def test_taubin_coefficients_satisfy_constraint_and_circle():
    p = arc((10.0, 20.0), 7.0, 0.0, 5.0, 30)
    A = taubin_circle_coefficients(p)
    y, x = p[:, 0], p[:, 1]
    # Eq. (26): a z + b x + c y + d = 0 on every point
    assert np.abs(A[0] * (x * x + y * y) + A[1] * x + A[2] * y + A[3]).max() < 1e-10
    # Eq. (29) / (32): A^T N A = 1
    zb, xb, yb = np.mean(x * x + y * y), x.mean(), y.mean()
    N = np.array([[4 * zb, 2 * xb, 2 * yb, 0], [2 * xb, 1, 0, 0], [2 * yb, 0, 1, 0], [0, 0, 0, 0]])
    assert A @ N @ A == pytest.approx(1.0, rel=1e-12)
    assert -A[1] / (2 * A[0]) == pytest.approx(20.0, abs=1e-9)
    assert -A[2] / (2 * A[0]) == pytest.approx(10.0, abs=1e-9)


def test_taubin_noisy_points_unbiased_enough(rng):
    p = arc((50.0, 60.0), 40.0, 0.0, 2 * math.pi, 400) + rng.normal(0, 0.3, (400, 2))
    f = fit_circle_taubin(p)
    assert abs(f.radius - 40.0) < 0.05
    assert math.hypot(f.center_rc[0] - 50, f.center_rc[1] - 60) < 0.05
    assert f.rms == pytest.approx(0.3, rel=0.15)


@pytest.mark.parametrize(
    "pts",
    [
        np.zeros((2, 2)),
        np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]),
        np.array([[1.0, 1.0]] * 5),
        np.array([[0.0, np.nan], [1.0, 2.0], [3.0, 1.0]]),
        np.zeros((4, 3)),
    ],
)
def test_taubin_degenerate_inputs_raise(pts):
    with pytest.raises(DegenerateFitError):
        fit_circle_taubin(pts)
    assert issubclass(DegenerateFitError, LimbInputError)


def test_circle_from_three_and_collinear():
    p = arc((3.0, -4.0), 12.5, 0.1, 2.0, 3)
    c, r = circle_from_three(p[0], p[1], p[2])
    assert np.allclose(c, [3.0, -4.0], atol=1e-10) and r == pytest.approx(12.5, abs=1e-10)
    c, r = circle_from_three(np.array([0.0, 0]), np.array([1.0, 1]), np.array([2.0, 2]))
    assert np.isinf(r) and np.isnan(c).all()


def test_circle_residuals_sign():
    r = circle_residuals(np.array([[0.0, 12.0], [0.0, 8.0]]), (0.0, 0.0), 10.0)
    assert np.allclose(r, [2.0, -2.0])


def _ellipse_points(c, a, b, ang, n=60, t0=0.0, t1=2 * math.pi):
    t = np.linspace(t0, t1, n, endpoint=False)
    u, v = a * np.cos(t), b * np.sin(t)
    x = c[1] + u * math.cos(ang) - v * math.sin(ang)
    y = c[0] + u * math.sin(ang) + v * math.cos(ang)
    return np.c_[y, x]


@pytest.mark.parametrize("ang", [0.0, 0.3, -1.2, math.pi / 2])
def test_direct_ellipse_exact(ang):
    p = _ellipse_points((20.0, 10.0), 80.0, 50.0, ang)
    e = fit_ellipse_direct(p)
    assert np.allclose(e.center_rc, (20.0, 10.0), atol=1e-7)
    assert np.allclose(e.semi_axes, (80.0, 50.0), atol=1e-7)
    d = (e.angle_rad - ang + math.pi / 2) % math.pi - math.pi / 2
    assert abs(d) < 1e-8
    assert e.rms < 1e-7


def test_direct_ellipse_partial_arc_noisy(rng):
    p = _ellipse_points((300.0, 400.0), 200.0, 190.0, 0.4, n=300, t0=0.0, t1=3.5)
    e = fit_ellipse_direct(p + rng.normal(0, 0.2, p.shape))
    assert math.hypot(e.center_rc[0] - 300, e.center_rc[1] - 400) < 3.0
    assert e.semi_axes[0] == pytest.approx(200.0, abs=4.0)


def test_ellipse_residuals_against_dense_sampling(rng):
    c, a, b, ang = (5.0, -3.0), 30.0, 12.0, 0.7
    q = rng.uniform(-40, 40, (200, 2)) + np.array(c)
    dense = _ellipse_points(c, a, b, ang, n=200000)
    exact = ellipse_residuals(q, c, (a, b), ang)
    brute = np.min(np.hypot(q[:, None, 0] - dense[None, ::10, 0], q[:, None, 1] - dense[None, ::10, 1]), axis=1)
    assert np.allclose(np.abs(exact), brute, atol=5e-3)
    inside = ((np.cos(ang) * (q[:, 1] - c[1]) + np.sin(ang) * (q[:, 0] - c[0])) / a) ** 2 + (
        (-np.sin(ang) * (q[:, 1] - c[1]) + np.cos(ang) * (q[:, 0] - c[0])) / b
    ) ** 2 < 1
    assert np.all((exact < 0) == inside)
    # on the ellipse: zero; at the centre: -b
    assert np.abs(ellipse_residuals(_ellipse_points(c, a, b, ang, 50), c, (a, b), ang)).max() < 1e-9
    assert ellipse_residuals(np.array([c]), c, (a, b), ang)[0] == pytest.approx(-b)


def test_ellipse_degenerate():
    with pytest.raises(DegenerateFitError):
        fit_ellipse_direct(np.zeros((4, 2)))
    with pytest.raises(DegenerateFitError):
        fit_ellipse_direct(np.c_[np.arange(10.0), 2 * np.arange(10.0)])
