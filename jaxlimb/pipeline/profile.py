"""The pipeline's side of the physical limb profile: the accepted range of the fitted ``L`` and the
sphere whose image has a given centre and mean radius.

The model itself (:data:`LIMB_PROFILE`, :func:`limb_profile_intensity`, its Jacobian) lives in
:mod:`jaxlimb.models.lunar_lambert`; its names are re-exported here for older imports.
"""

from __future__ import annotations

import math

import numpy as np

from ..models.lunar_lambert import (  # noqa: F401  (the model moved to jaxlimb.models; re-exported)
    LIMB_PROFILE as LIMB_PROFILE,
    PHYSICAL_L as PHYSICAL_L,
    PROFILE_FIXED as PROFILE_FIXED,
    LimbProfileParams as LimbProfileParams,
    limb_profile_intensity as limb_profile_intensity,
    lunar_lambert_weight as lunar_lambert_weight,
)


def l_band(fit) -> tuple[float, float]:
    """The accepted range of ``L`` for ``fit`` (a :class:`~jaxlimb.fitting.LimbFit` of :data:`LIMB_PROFILE`):
    :data:`PHYSICAL_L` widened by 3 sigma of ``L`` when ``L`` was estimated."""
    if "L" not in fit.free:
        return (-math.inf, math.inf)
    i = list(fit.free).index("L")
    s = float(np.sqrt(max(float(np.asarray(fit.covariance)[i, i]), 0.0)))
    return (PHYSICAL_L[0] - 3.0 * s, PHYSICAL_L[1] + 3.0 * s)


__all__ = [
    "LIMB_PROFILE",
    "LimbProfileParams",
    "PHYSICAL_L",
    "PROFILE_FIXED",
    "l_band",
    "limb_profile_intensity",
    "lunar_lambert_weight",
]
