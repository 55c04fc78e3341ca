"""The paper's printed derivatives, transcribed as printed (NumPy, not the package's code), against ``jax.jacfwd`` of
the paper's intensity: Eq. 14 (the linear sigmoid, Eq. 12-13), Eq. 17 (the circular sigmoid, Eq. 16) and the
elliptical set of Sec. V-C (Mortari, D'Souza & Zanetti 2016, J. Spacecraft and Rockets 53(3)).

Every printed formula agrees with the derivative of its intensity to 1e-10 (the metric of ``jaxlimb gradcheck``).  The elliptical set is printed without
the transform from pixels to the ellipse's frame: the paper refers to Appendix A (Eq. 19-20), which gives the
transform from pixels to the focal plane instead, with no centre and no rotation.  The set holds for the frame whose
``x`` runs along the ``a`` axis rotated by ``theta`` from ``+col`` toward ``-row`` about ``(r0, c0)`` (``y`` toward
``-row`` at ``theta = 0``); with the rotation the other way round its ``r0``, ``c0`` and ``theta`` formulas are wrong
(:func:`test_elliptical_set_needs_the_transform_it_does_not_print`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)

RNG = np.random.default_rng(20161)


def _points(n: int = 200):
    return RNG.uniform(-60, 60, (n, 2)) + np.array([120.0, 140.0])


# ----------------------------------------------------------------------------- Eq. 12-14
def _lsf(p, x):  # Eq. 12
    xt, ymax, ymin, k = p
    return ymax + (ymin - ymax) / (1.0 + jnp.exp(k * (xt - x)))


def _eq14(p, x):
    """Eq. 14 as printed: columns (x_t, y_max, y_min, k) with alpha_i = e^{k (x_t - x_i)} (Eq. 13)."""
    xt, ymax, ymin, k = p
    a = np.exp(k * (xt - x))
    d_ymin = 1.0 / (1.0 + a)
    d_ymax = a / (1.0 + a)
    d_xt = -(ymin - ymax) * a * k / (1.0 + a) ** 2
    d_k = -(ymin - ymax) * a / (1.0 + a) ** 2 * (xt - x)
    # and its printed alternate forms
    np.testing.assert_allclose(d_ymax, a * d_ymin, rtol=1e-13)
    np.testing.assert_allclose(d_xt, -d_ymin * d_ymax * (ymin - ymax) * k, rtol=1e-12)
    np.testing.assert_allclose(d_k, (xt - x) / k * d_xt, rtol=1e-12, atol=1e-300)
    return np.stack([d_xt, d_ymax, d_ymin, d_k], axis=1)


# ----------------------------------------------------------------------------- Eq. 16-17
def _csf(p, rc):  # Eq. 16
    r0, c0, re, k, ymax, ymin = p
    d = jnp.sqrt((c0 - rc[:, 1]) ** 2 + (r0 - rc[:, 0]) ** 2)
    return ymax + (ymin - ymax) / (1.0 + jnp.exp(k * (re - d)))


def _eq17(p, rc):
    """Eq. 17 as printed: columns (r_0, c_0, r_e, k, y_max, y_min)."""
    r0, c0, re, k, ymax, ymin = p
    r, c = rc[:, 0], rc[:, 1]
    b = np.sqrt((c0 - c) ** 2 + (r0 - r) ** 2)
    a = np.exp(k * (re - b))
    g = (ymin - ymax) * a / (1.0 + a) ** 2
    return np.stack([g * k * (r0 - r) / b, g * k * (c0 - c) / b, -g * k, -g * (re - b), a / (1.0 + a), 1.0 / (1.0 + a)],
                    axis=1)


# ----------------------------------------------------------------------------- Sec. V-C
def _frame(p, rc, sign: float = 1.0):
    """The ellipse's frame: ``sign = 1`` the rotation of the module docstring, ``-1`` the other way round."""
    r0, c0, _, th = p[:4]
    dc, dr = rc[:, 1] - c0, r0 - rc[:, 0]  # x toward +col, y toward -row (the focal plane of Eq. 20)
    ct, st = jnp.cos(th), sign * jnp.sin(th)
    return dc * ct + dr * st, -dc * st + dr * ct


def _esf(p, rc, sign: float = 1.0):
    _, _, a, _, rho, k, ymax, ymin = p
    x, y = _frame(p, rc, sign)
    d = jnp.sqrt(rho**2 * x**2 + y**2)
    return ymax + (ymin - ymax) / (1.0 + jnp.exp(k * (rho * a - d)))


def _elliptical_set(p, rc, sign: float = 1.0):
    """The elliptical set as printed: columns (r_0, c_0, a, theta, y_max, y_min, k); rho held (not printed)."""
    _, _, a_, th, rho, k, ymax, ymin = p
    x, y = (np.asarray(v) for v in _frame(p, rc, sign))
    b = np.sqrt(rho**2 * x**2 + y**2)
    al = np.exp(k * (rho * a_ - b))
    g = (ymin - ymax) * al / (1.0 + al) ** 2
    s, c = np.sin(th), np.cos(th)
    return np.stack([g * k * (rho**2 * x * s + y * c) / b, g * k * (y * s - rho**2 * x * c) / b, -g * k * rho,
                     g * k * x * y * (rho**2 - 1.0) / b, al / (1.0 + al), 1.0 / (1.0 + al), -g * (rho * a_ - b)], axis=1)


def _rel(printed: np.ndarray, exact: np.ndarray) -> float:
    """``jaxlimb gradcheck``'s relative error: an entry four orders below its column against 1e-4 of the column (the
    naive intensity's autodiff rounds ``1 - 1/(1 + alpha)`` where the printed ``alpha/(1 + alpha)`` does not)."""
    scale = np.max(np.abs(exact), axis=0)
    return float(np.max(np.abs(printed - exact) / np.maximum(np.abs(exact), 1e-4 * scale)))


@pytest.mark.parametrize("k", [0.1, 0.9, 3.0])
def test_eq14_as_printed_is_the_derivative_of_eq12(k):
    p = np.array([50.3, 150.0, 20.0, k])
    x = np.linspace(0.0, 100.0, 301)
    exact = np.asarray(jax.jacfwd(_lsf)(jnp.asarray(p), jnp.asarray(x)))
    assert _rel(_eq14(p, x), exact) < 1e-10


@pytest.mark.parametrize("k", [0.3, 3.0])
def test_eq17_as_printed_is_the_derivative_of_eq16(k):
    p = np.array([120.3, 139.6, 40.0, k, 200.0, 20.0])
    rc = _points()
    exact = np.asarray(jax.jacfwd(_csf)(jnp.asarray(p), jnp.asarray(rc)))
    assert _rel(_eq17(p, rc), exact) < 1e-10


@pytest.mark.parametrize("theta", [0.0, 0.4, -1.2])
def test_elliptical_set_as_printed_is_the_derivative_of_the_esf(theta):
    p = np.array([120.3, 139.6, 45.0, theta, 0.8, 1.5, 200.0, 20.0])
    rc = _points()
    exact = np.asarray(jax.jacfwd(_esf)(jnp.asarray(p), jnp.asarray(rc)))[:, [0, 1, 2, 3, 6, 7, 5]]
    assert _rel(_elliptical_set(p, rc), exact) < 1e-10


def test_elliptical_set_needs_the_transform_it_does_not_print():
    """With the rotation the other way round (an equally natural reading of "rotated by theta") the printed r_0,
    c_0 and theta columns are not the derivatives of the ESF: O(1) errors; the others still hold."""
    p = np.array([120.3, 139.6, 45.0, 0.4, 0.8, 1.5, 200.0, 20.0])
    rc = _points()
    exact = np.asarray(jax.jacfwd(lambda q, x: _esf(q, x, -1.0))(jnp.asarray(p), jnp.asarray(rc)))[:, [0, 1, 2, 3, 6, 7, 5]]
    printed = _elliptical_set(p, rc, -1.0)
    errs = [_rel(printed[:, [j]], exact[:, [j]]) for j in range(7)]
    assert min(errs[0], errs[1], errs[3]) > 0.1
    assert max(errs[2], errs[4], errs[5], errs[6]) < 1e-10


def test_the_package_follows_the_printed_formulas():
    """The package's ESF and its Jacobian are the printed set in the frame of the module docstring."""
    from jaxlimb.models import ELLIPSE, EllipseParams, ellipse_coords

    p = np.array([120.3, 139.6, 45.0, 0.4, 0.8, 1.5, 200.0, 20.0])
    ep = EllipseParams(*p)
    rc = _points()
    x, y = ellipse_coords(ep, jnp.asarray(rc))
    fx, fy = _frame(p, rc)
    np.testing.assert_allclose(np.asarray(x), np.asarray(fx), atol=1e-12)
    np.testing.assert_allclose(np.asarray(y), np.asarray(fy), atol=1e-12)
    J = np.asarray(ELLIPSE.jacobian(ep, jnp.asarray(rc)))  # (r0, c0, a, theta, rho, k, ymax, ymin)
    assert _rel(_elliptical_set(p, rc), J[:, [0, 1, 2, 3, 6, 7, 5]]) < 1e-10
