"""Numerical tools every layer may use: the central-difference Jacobian of a map that is not written in JAX (the
body-centre maps of a fitted limb, the Earth's range iteration), for the delta method :math:`G C G^\\top` of a fit's
covariance."""

from __future__ import annotations

import numpy as np

from .errors import LimbInputError


def numerical_jacobian(fn, x: np.ndarray, step: np.ndarray | float = 1e-4) -> np.ndarray:  # noqa: ANN001
    """Central-difference Jacobian ``(m, p)`` of ``fn: (p,) -> (m,)`` at ``x`` (error ``O(step^2)``)."""
    x = np.asarray(x, dtype=float)
    h = np.broadcast_to(np.asarray(step, dtype=float), x.shape)
    if np.any(h <= 0):
        raise LimbInputError(f"`step` must be > 0, got {step!r}")
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h[i]
        cols.append((np.atleast_1d(fn(x + e)) - np.atleast_1d(fn(x - e))) / (2.0 * h[i]))
    return np.stack(cols, axis=-1)


__all__ = ["numerical_jacobian"]
