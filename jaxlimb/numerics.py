"""Numerical tools every layer may use: the central-difference Jacobian of a map that is not written in JAX (the
body-centre maps of a fitted limb, the Earth's range iteration), for the delta method :math:`G C G^\\top` of a fit's
covariance; the BLAS thread pools of a computation whose answer must not depend on how a threaded BLAS splits its
sums."""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Iterator
from typing import Any

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


@functools.cache
def blas_controller() -> Any:
    """The process's BLAS thread pools (``threadpoolctl.ThreadpoolController``), found once.

    SciPy's arithmetic around MINPACK (dot products over ~10^4 pixels) runs under one thread: a threaded BLAS spends
    more in waking its threads than it saves there.

    Returns
    -------
    threadpoolctl.ThreadpoolController
    """
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with one BLAS thread: a threaded BLAS splits a long dot product's sum by its thread count, so the
    last digits of a product depend on the machine's load; under one thread they do not (a pipeline run killed and
    resumed gives the same bytes as one run)."""
    with blas_controller().limit(limits=1, user_api="blas"):
        yield


__all__ = ["blas_controller", "numerical_jacobian", "one_blas_thread"]
