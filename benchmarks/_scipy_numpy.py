"""The strongest SciPy baseline a user would write for the circular-sigmoid fit.

``scipy.optimize.least_squares(method="lm")`` (MINPACK) with the model (Eq. 16) and its
analytic Jacobian (Eq. 17) written in NumPy, computed in one pass and cached so that MINPACK's
Jacobian call at a point it has just evaluated costs nothing.  No JAX anywhere in the loop
(``ScipyLeastSquares`` in the package calls the jitted JAX model from SciPy's loop instead, and
pays JAX's dispatch and device-to-host copies on every call: kept as a second row).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.special import expit


def circle_value_and_jac(x: np.ndarray, rc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (16) and the Jacobian of Eq. (17), columns ``(r0, c0, radius, k, ymax, ymin)``."""
    r0, c0, radius, k, ymax, ymin = x
    dr = r0 - rc[:, 0]
    dc = c0 - rc[:, 1]
    beta = np.hypot(dr, dc)
    z = k * (beta - radius)
    s, sc = expit(z), expit(-z)
    g = (ymin - ymax) * s * sc
    jt = np.empty((6, rc.shape[0]))  # built transposed: contiguous columns (MINPACK is column-major)
    gk_b = g * k / beta
    np.multiply(gk_b, dr, out=jt[0])
    np.multiply(gk_b, dc, out=jt[1])
    np.multiply(g, -k, out=jt[2])
    np.multiply(g, beta - radius, out=jt[3])
    jt[4] = sc
    jt[5] = s
    return ymax * sc + ymin * s, jt.T


def fit_circle_scipy(rc: np.ndarray, z: np.ndarray, x0: np.ndarray, free: np.ndarray | None = None,
                     tol: float = 1e-12, max_nfev: int = 256 * 7) -> tuple[np.ndarray, int, bool]:
    """Fit the circular sigmoid with MINPACK LM; ``free`` selects the estimated parameters.

    Returns ``(x, njev, success)``.
    """
    x0 = np.asarray(x0, dtype=float)
    free = np.arange(6) if free is None else np.asarray(free)
    cache: dict[str, object] = {}

    def full(y: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[free] = y
        return x

    def fun(y: np.ndarray) -> np.ndarray:
        f, jac = circle_value_and_jac(full(y), rc)
        cache["y"], cache["jac"] = y.copy(), jac
        return f - z

    def jac(y: np.ndarray) -> np.ndarray:
        if "y" not in cache or not np.array_equal(cache["y"], y):
            fun(y)
        return cache["jac"][:, free]  # type: ignore[index]

    sol = least_squares(fun, x0[free], jac=jac, method="lm", xtol=tol, ftol=tol, gtol=tol, max_nfev=max_nfev)
    return full(sol.x), int(sol.njev or sol.nfev), bool(sol.status > 0)
