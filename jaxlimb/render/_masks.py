"""Pixel masks shared by the renderers."""

from __future__ import annotations

import numpy as np


def boundary_mask(values: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Pixels whose value differs from one of their 4-neighbours' (both pixels of such a pair are marked); with
    ``valid``, only pairs of two valid pixels count."""
    out = np.zeros(values.shape, bool)
    d = values[1:] != values[:-1]
    if valid is not None:
        d &= valid[1:] & valid[:-1]
    out[1:] |= d
    out[:-1] |= d
    d = values[:, 1:] != values[:, :-1]
    if valid is not None:
        d &= valid[:, 1:] & valid[:, :-1]
    out[:, 1:] |= d
    out[:, :-1] |= d
    return out
