"""Synthetic limbs with exact truth for the posterior's studies and tests: circular-sigmoid pixels on an arc."""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ...errors import LimbInputError
from ...models import CIRCLE, CircleParams, LimbParams


@dataclass(frozen=True)
class SyntheticLimb:
    """Pixels of a circular-sigmoid limb with exact truth (for studies and tests)."""

    coords: np.ndarray
    z: np.ndarray
    truth: LimbParams
    sigma: float
    arc_deg: float


def synthetic_circle(radius: float = 150.0, k: float = 3.0, ymax: float = 200.0, ymin: float = 20.0,
                     sigma: float = 10.0, arc_deg: float = 360.0, arc_center_deg: float = 0.0,
                     annulus: float = 6.0, center_rc: tuple[float, float] | None = None, seed: int = 0) -> SyntheticLimb:
    """Pixels within ``annulus`` px of a circular limb (Eq. 16), on an arc, plus Gaussian noise.

    The arc is ``arc_deg`` wide, centred on the position angle ``arc_center_deg`` (from
    ``+col`` toward ``-row``): 360 = full disc, 180 = the lit limb of a crescent or gibbous
    Moon (the limb between the cusps is always a half circle), 60 = a short arc.  The
    intensities are the model itself, so the fit's model is exact and the CRLB applies.

    Parameters
    ----------
    radius, k, ymax, ymin : float
        True circular-sigmoid parameters: radius (px), steepness (1/px), intensities inside and outside (DN).
    sigma : float
        Standard deviation of the Gaussian noise (DN).
    arc_deg, arc_center_deg : float
        Width of the arc and its central position angle (degrees).
    annulus : float
        Half-width of the pixel band around the limb (px).
    center_rc : tuple of float, optional
        True centre (row, col) px; default ``(half + 0.3, half - 0.4)``, off the pixel grid, with
        ``half = radius + annulus + 2``.
    seed : int
        Seed of the noise (``numpy.random.default_rng``).

    Returns
    -------
    SyntheticLimb
        Pixels ``(n, 2)`` as (row, col), noisy intensities ``(n,)``, the truth (:class:`CircleParams`), ``sigma``
        and ``arc_deg``.
    """
    for name, v in (("radius", radius), ("k", k), ("sigma", sigma), ("annulus", annulus)):
        if not (math.isfinite(v) and v > 0):
            raise LimbInputError(f"`{name}` must be a finite number > 0, got {v!r}")
    if not 0 < arc_deg <= 360:
        raise LimbInputError(f"`arc_deg` must be in (0, 360], got {arc_deg!r}")
    half = radius + annulus + 2
    r0, c0 = center_rc if center_rc is not None else (half + 0.3, half - 0.4)
    rr, cc = np.mgrid[int(np.floor(r0 - half)):int(np.ceil(r0 + half)) + 1, int(np.floor(c0 - half)):int(np.ceil(c0 + half)) + 1]
    rc = np.stack([rr.ravel(), cc.ravel()], -1).astype(float)
    d = np.hypot(rc[:, 0] - r0, rc[:, 1] - c0)
    ang = np.degrees(np.arctan2(-(rc[:, 0] - r0), rc[:, 1] - c0))
    dang = (ang - arc_center_deg + 180.0) % 360.0 - 180.0
    sel = (np.abs(d - radius) <= annulus) & (np.abs(dang) <= arc_deg / 2.0)
    rc = rc[sel]
    truth = CircleParams(float(r0), float(c0), float(radius), float(k), float(ymax), float(ymin))
    clean = np.asarray(CIRCLE.intensity(truth, jnp.asarray(rc)))
    z = clean + sigma * np.random.default_rng(seed).standard_normal(clean.size)
    return SyntheticLimb(rc, z, truth, float(sigma), float(arc_deg))


__all__ = ["SyntheticLimb", "synthetic_circle"]
