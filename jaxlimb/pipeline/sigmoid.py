"""The sigmoid fits every body strategy shares: a limb model fitted to a set of pixels padded to a bucket (few compiled
programs across images), Check 5 on its convergence, the model's intensities and Fisher information at an estimate."""

from __future__ import annotations

import functools

import jax
import numpy as np

from .._programs import stored_jit
from ..errors import ConvergenceError
from ..fitting import bucket_size, fit, LimbFit, solver_from_name
from .options import LocateOptions
from .stages import FitData


#: Ratio between the Gaussian sigma of an edge and the logistic scale 1/k that matches it.
LOGISTIC_TO_GAUSS = 1.7


#: Initial steepness (1/px): a logistic matching a ~1.1 px Gaussian PSF.
K_INIT = 1.5


# ============================================================================ fits
def levels_held(options: LocateOptions) -> tuple[str, ...]:
    """The edge parameters held fixed: none with ``estimate_k``, else ``k`` and the levels (the papers' setting).

    Parameters
    ----------
    options : LocateOptions

    Returns
    -------
    tuple of str
        ``()`` or ``("k", "ymax", "ymin")``.
    """
    return () if options.estimate_k else ("k", "ymax", "ymin")


def pad_coords(coords: np.ndarray) -> np.ndarray:
    """``coords`` ``(n, 2)`` padded to :func:`~jaxlimb.fitting.bucket_size` of ``n`` with copies of the first pixel: the
    shapes the model's column programs (:func:`columns`) are compiled for, one per bucket rather than per limb.

    Parameters
    ----------
    coords : array_like (n, 2)
        Pixels ``(row, col)``.

    Returns
    -------
    np.ndarray (m, 2)
        ``m = bucket_size(n)``; the first ``n`` rows are ``coords``.
    """
    coords = np.asarray(coords, float)
    n = coords.shape[0]
    return np.concatenate([coords, np.repeat(coords[:1], bucket_size(n) - n, axis=0)])


def pad_bucket(data: FitData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pad to the next size ``2^k`` or ``1.5 * 2^k`` (>= 4096) with zero-weight copies of the first pixel.

    The sizes are those of :func:`jaxlimb.fitting.fit.bucket_size`, starting at 4096: few
    distinct compiled programs across images (compiling costs seconds, a fit of 10^4 pixels
    milliseconds) for at most 1.5x the work (powers of two alone cost up to 2x: 4887 pixels would run as
    8192 instead of 6144).

    Parameters
    ----------
    data : FitData
        ``n`` pixels; ``weights`` ``None`` means unit weights.

    Returns
    -------
    coords : np.ndarray (m, 2)
        The pixels ``(row, col)`` padded to ``m >= n``.
    z : np.ndarray (m,)
        Their intensities.
    weights : np.ndarray (m,)
        Their weights, 0 on the padding.
    """
    n = data.z.shape[0]
    size = max(4096, bucket_size(n))
    w = np.ones(n) if data.weights is None else np.asarray(data.weights, dtype=float)
    pad = size - n
    if pad <= 0:
        return data.coords, data.z, w
    return (np.concatenate([data.coords, np.repeat(data.coords[:1], pad, axis=0)]),
            np.concatenate([data.z, np.repeat(data.z[:1], pad)]),
            np.concatenate([w, np.zeros(pad)]))


def run_fit(model, data: FitData, init, options: LocateOptions, fixed, solver=None) -> LimbFit:
    """``model`` fitted to ``data`` from ``init`` (``fixed`` held; the options' solver unless ``solver``), padded to a
    bucket (:func:`pad_bucket`); Check 5: no convergence or non-finite parameters is a
    :class:`~jaxlimb.errors.ConvergenceError`.

    Parameters
    ----------
    model : LimbModel
        The intensity model (CSF, ESF, a limb profile ...: :mod:`jaxlimb.models`).
    data : FitData
        Pixels ``(row, col)``, intensities and weights.
    init : the model's parameter container
        Starting point.
    options : LocateOptions
        Solver name and ``max_steps``.
    fixed : tuple of str
        Names of the parameters held at ``init``.
    solver : optional
        A solver object or name for :func:`jaxlimb.fitting.fit`, overriding the options'.

    Returns
    -------
    LimbFit
        The converged fit (parameters, covariance over the free ones, ``sigma2``, steps).
    """
    coords, z, w = pad_bucket(data)
    res = fit(model, coords, z, init, solver if solver is not None else solver_from_name(options.solver), fixed=fixed,
              weights=w,
              max_steps=options.max_steps, throw=False)
    if not bool(res.converged):
        reason = res.message.split(" Try increasing")[0]  # the solver's advice names an argument locate sets itself
        raise ConvergenceError(
            f"Check 5: the {model.name} sigmoid fit ({res.solver}) did not converge within {options.max_steps} "
            f"iterations: {reason}"
        )
    p = res.params
    vals = np.array([float(getattr(p, n)) for n in model.param_names])
    if not np.all(np.isfinite(vals)):
        raise ConvergenceError(f"Check 5: the {model.name} sigmoid fit returned non-finite parameters {vals.tolist()}")
    return res


@stored_jit(static_non_arrays=True)
def _predict_jit(model, params, coords):
    return model.intensity(params, coords)


@stored_jit
def _columns(model, params, coords):
    return model.intensity_and_jacobian_columns(params, coords)


def columns(model):
    """``model``'s jitted ``(intensity, columns)``: its analytic Jacobian columns, one compiled program per model and
    bucket (stored: :func:`jaxlimb._programs.stored_jit`) that the fit's Fisher matrix and the model-error terms share.

    Parameters
    ----------
    model : LimbModel
        The limb model.

    Returns
    -------
    callable
        ``(params, coords) -> (intensity (n,), columns)``.
    """
    return functools.partial(_columns, model)


def predict(model, params, coords: np.ndarray) -> np.ndarray:
    """Model intensities at ``coords`` (jitted on the padded shapes of :func:`pad_bucket`: no per-image recompiles).

    Parameters
    ----------
    model : LimbModel
    params : the model's parameter container
    coords : np.ndarray (n, 2)
        Pixels ``(row, col)``.

    Returns
    -------
    np.ndarray (n,)
        Intensities in the units of ``params``' levels.
    """
    n = coords.shape[0]
    cp, _, _ = pad_bucket(FitData(coords, np.zeros(n), None, 0.0, 1.0))
    return np.asarray(_predict_jit(model, params, jax.device_put(np.asarray(cp))))[:n]


def fisher_information(model, params, data: FitData, fixed: tuple[str, ...], sigma: float) -> np.ndarray:
    """Fisher matrix ``J^T diag(w^2) J / sigma^2`` over the free parameters (the information of
    :func:`jaxlimb.analysis.crlb.crlb` with per-pixel noise ``sigma / w_i``), from the model's analytic columns on the
    padded shapes of :func:`pad_coords` (:func:`columns`).

    Parameters
    ----------
    model : LimbModel
    params : the model's parameter container
        The estimate.
    data : FitData
        Pixels and weights ``w_i`` (``None``: 1).
    fixed : tuple of str
        Parameters held fixed (not in the matrix).
    sigma : float
        Noise level in the units of ``data.z``.

    Returns
    -------
    np.ndarray (p, p)
        ``p`` the number of free parameters, in the model's parameter order.
    """
    n = data.z.shape[0]
    w = np.ones(n) if data.weights is None else np.asarray(data.weights, dtype=float)
    _, cols = columns(model)(params, jax.device_put(pad_coords(data.coords)))  # the model-error terms' program
    J = np.stack([np.asarray(cols[i])[:n] for i in model.free_indices(fixed)], axis=1)
    return (J.T @ (J * (w * w)[:, None])) / sigma**2


def replace_params(p, **kw):
    """A copy of a parameter container with some fields replaced (floats, not 0-d arrays).

    Parameters
    ----------
    p : parameter container
        Any :mod:`jaxlimb.models` parameter module with a ``replace`` method.
    **kw : float
        Field name -> new value.

    Returns
    -------
    parameter container
        Of the type of ``p``.
    """
    return p.replace(**{k: float(v) for k, v in kw.items()})


__all__ = ["K_INIT", "LOGISTIC_TO_GAUSS", "columns", "fisher_information", "levels_held", "pad_bucket", "pad_coords", "predict", "replace_params", "run_fit"]
