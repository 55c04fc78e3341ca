"""Pixel sets of a fit: the buckets they are padded to, and the checks of :func:`~jaxlimb.fitting.fit`'s inputs.

Pixel sets are padded to a *bucket* size (:func:`bucket_size`) with zero-weight copies of a real pixel, so
images whose pixel counts fall in the same bucket reuse one compiled program, and padded pixels contribute
exactly nothing (no NaN).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import LimbInputError
from ..models import LimbModel, LimbParams

_MIN_BUCKET = 256


# ============================================================================ buckets
def bucket_size(n: int) -> int:
    """Padded length for ``n`` pixels: the next of 256, 384, 512, 768, 1024, 1536, ...

    Buckets grow by factors of 1.5 and 4/3 alternately, so padding wastes at
    most 50 % and the number of distinct compiled shapes stays logarithmic.

    Parameters
    ----------
    n : int
        Number of pixels.

    Returns
    -------
    int
        The bucket: the smallest size of the sequence that holds ``n``.
    """
    if n <= _MIN_BUCKET:
        return _MIN_BUCKET
    k = math.floor(math.log2(n))
    for b in (1 << k, 3 << (k - 1), 1 << (k + 1)):
        if b >= n:
            return b
    return 1 << (k + 1)  # pragma: no cover


def pad_pixels(coords: np.ndarray, z: np.ndarray, w: np.ndarray, size: int) -> tuple[np.ndarray, ...]:
    """Pad one pixel set to ``size`` with zero-weight copies of its first pixel.

    Parameters
    ----------
    coords : np.ndarray (n, 2) or (n,)
        Pixel coordinates, ``(row, col)`` (positions for the linear model).
    z, w : np.ndarray (n,)
        Intensities and weights.
    size : int
        Padded length (>= ``n``), usually :func:`bucket_size` of ``n``.

    Returns
    -------
    tuple of np.ndarray
        ``(coords, z, w)`` of length ``size``; the padding has weight 0.

    Raises
    ------
    LimbInputError
        ``n > size``.
    """
    n = z.shape[0]
    if n > size:
        raise LimbInputError(f"cannot pad {n} pixels into a bucket of {size}")
    pad = size - n
    if pad == 0:
        return coords, z, w
    coords_p = np.concatenate([coords, np.repeat(coords[:1], pad, axis=0)], axis=0)
    z_p = np.concatenate([z, np.repeat(z[:1], pad)])
    w_p = np.concatenate([w, np.zeros(pad, dtype=w.dtype)])
    return coords_p, z_p, w_p


def pack_pixels(
    coords: Sequence[np.ndarray], z: Sequence[np.ndarray], weights: Sequence[np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stack pixel sets of different sizes into one padded batch ``(B, N, ...)`` with weights.

    ``N`` is the bucket of the largest set, so batches of similar images share a
    compiled program.

    Parameters
    ----------
    coords : sequence of np.ndarray (n_b, 2)
        Pixel coordinates ``(row, col)`` of each set (``(n_b,)`` for the linear model).
    z : sequence of np.ndarray (n_b,)
        Intensities of each set.
    weights : sequence of np.ndarray (n_b,), optional
        Weights of each set; ``None``: all 1.

    Returns
    -------
    tuple of np.ndarray
        ``coords`` ``(B, N, 2)``, ``z`` and ``weights`` ``(B, N)`` (padding: weight 0), as :func:`fit_batch` takes
        them.
    """
    if len(coords) != len(z) or len(coords) == 0:
        raise LimbInputError(f"`coords` and `z` must be non-empty and of equal length, got {len(coords)} and {len(z)}")
    ws = weights if weights is not None else [np.ones(len(zi)) for zi in z]
    size = bucket_size(max(len(zi) for zi in z))
    out = [pad_pixels(np.asarray(c, float), np.asarray(zi, float), np.asarray(wi, float), size) for c, zi, wi in zip(coords, z, ws)]
    return tuple(np.stack([o[i] for o in out]) for i in range(3))  # type: ignore[return-value]


# ============================================================================ validation
def validate_inputs(
    model: LimbModel, coords: Any, z: Any, init: LimbParams, fixed: Sequence[str], weights: Any, batched: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, ...]]:
    """Check the inputs of :func:`~jaxlimb.fitting.fit` or :func:`~jaxlimb.fitting.fit_batch` and convert them.

    Parameters
    ----------
    model, coords, z, init, fixed, weights
        As :func:`~jaxlimb.fitting.fit` (with a leading batch axis ``B`` when ``batched``).
    batched : bool
        Whether the inputs carry the leading batch axis of :func:`~jaxlimb.fitting.fit_batch`.

    Returns
    -------
    coords, z, w : np.ndarray
        The pixels as float arrays; ``w`` is all 1 when ``weights`` is ``None``.
    theta : np.ndarray (p,) or (B, p)
        ``init`` as a vector in the model's field order.
    free_idx : tuple of int
        Indices of the parameters not in ``fixed``.

    Raises
    ------
    LimbInputError
        Wrong parameter type or shapes, unknown ``fixed`` names, nothing free, no or too few pixels, non-finite
        values, negative weights, a scale parameter (``radius``, ``a``, ``k``, ``rho``) <= 0.
    """
    free_idx = _free_indices(model, init, fixed)
    coords, z, w = _pixel_arrays(model, coords, z, weights, batched, len(free_idx))
    theta = _init_vector(model, init, z, batched)
    return coords, z, w, theta, free_idx


def _free_indices(model: LimbModel, init: LimbParams, fixed: Sequence[str]) -> tuple[int, ...]:
    """Indices of the parameters not in ``fixed``, after checking ``init``'s type and the names in ``fixed``."""
    if not isinstance(init, model.params_type):
        raise LimbInputError(
            f"`init` must be a {model.params_type.__name__} for the {model.name!r} model, got {type(init).__name__}"
        )
    unknown = sorted(set(fixed) - set(model.param_names))
    if unknown:
        raise LimbInputError(f"`fixed` names unknown parameters {unknown}; the {model.name!r} model has {list(model.param_names)}")
    free_idx = model.free_indices(fixed)
    if not free_idx:
        raise LimbInputError("`fixed` holds every parameter: nothing to estimate")
    return free_idx


def _pixel_arrays(model: LimbModel, coords: Any, z: Any, weights: Any, batched: bool,
                  q: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``coords``, ``z`` and the weights as checked float arrays (finite, shapes matching, weights >= 0, more
    pixels of positive weight than the ``q`` free parameters)."""
    coords = np.asarray(coords, dtype=float)
    z = np.asarray(z, dtype=float)
    lead = 1 if batched else 0
    want_coords_nd = lead + (1 if model.name == "linear" else 2)
    if coords.ndim != want_coords_nd or (model.name != "linear" and coords.shape[-1] != 2):
        shape = "(n,)" if model.name == "linear" else "(n, 2) as (row, col)"
        raise LimbInputError(f"`coords` must have shape {'(B, ' if batched else ''}{shape[1:] if batched else shape}, got {coords.shape}")
    n_shape = coords.shape[: lead + 1]
    if z.shape != n_shape:
        raise LimbInputError(f"`z` must have shape {n_shape} to match `coords`, got {z.shape}")
    if z.shape[-1] == 0:
        raise LimbInputError("`z` is empty: no pixels to fit")
    w = np.ones_like(z) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != z.shape:
        raise LimbInputError(f"`weights` must have shape {z.shape}, got {w.shape}")
    for name, arr in (("coords", coords), ("z", z), ("weights", w)):
        if not np.all(np.isfinite(arr)):
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise LimbInputError(f"`{name}` has a non-finite value {float(arr[tuple(bad)])!r} at index {tuple(int(b) for b in bad)}")
    if np.any(w < 0):
        raise LimbInputError(f"`weights` must be >= 0, got min {float(w.min())!r}")
    n_used = (w > 0).sum(axis=-1)
    if np.any(n_used <= q):
        raise LimbInputError(f"need more pixels than free parameters ({q}), got {int(np.min(n_used))}")
    return coords, z, w


def _init_vector(model: LimbModel, init: LimbParams, z: np.ndarray, batched: bool) -> np.ndarray:
    """``init`` as a vector ``(p,)`` or ``(B, p)`` in the model's field order (checked: finite, matching the data's
    batch, scale parameters > 0)."""
    theta = np.stack([np.asarray(getattr(init, n), dtype=float) for n in model.param_names], axis=-1)
    if theta.shape[-1:] != (len(model.param_names),) or (batched and theta.shape[0] != z.shape[0]):
        raise LimbInputError(f"`init` has shape {theta.shape[:-1]} but the data have batch shape {z.shape[:-1]}")
    if not np.all(np.isfinite(theta)):
        raise LimbInputError(f"`init` has non-finite values: {init}")
    for i, name in enumerate(model.param_names):
        if name in ("radius", "a", "k", "rho") and np.any(theta[..., i] <= 0):
            raise LimbInputError(f"`init.{name}` must be > 0, got {float(np.min(theta[..., i]))!r}")
    return theta
