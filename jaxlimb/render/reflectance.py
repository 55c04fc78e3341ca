r"""Reflectance (photometric) models of the truth renderer.

All functions return the radiance factor in units where a Lambert surface of
albedo 1 seen at normal incidence (:math:`\mu_0 = 1`) gives 1 (an I/F-like
scale).  :math:`\mu_0 = \cos i` (incidence), :math:`\mu = \cos e` (emission),
:math:`\alpha` the phase angle.  Unlit points (:math:`\mu_0 \le 0`) are 0.

* ``"lambert"``: :math:`\mu_0`.
* ``"lommel-seeliger"``: :math:`2\mu_0/(\mu_0+\mu)` (the factor 2 makes it 1 at
  :math:`\mu_0=\mu=1`); a dark, regolith-like surface with no limb darkening.
* ``"lunar-lambert"`` (McEwen 1991, 1996):
  :math:`L(\alpha)\,2\mu_0/(\mu_0+\mu) + (1 - L(\alpha))\,\mu_0`, with the lunar
  polynomial :math:`L(\alpha) = 1 + A\alpha + B\alpha^2 + C\alpha^3` (``alpha`` in
  degrees), :math:`A=-0.019`, :math:`B=2.42\cdot10^{-4}`, :math:`C=-1.46\cdot10^{-6}`
  (McEwen 1996, LPSC XXVII, "A precise lunar photometric function"), clipped to
  ``[0, 1]``: pure Lommel-Seeliger at full Moon, more Lambert-like at large phase.
* ``"uniform"``: 1 everywhere on the visible disk (an emitting, flat disk that ignores
  the Sun) -- used to test the limb geometry.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError

__all__ = ["LUNAR_LAMBERT_MCEWEN", "REFLECTANCE_MODELS", "lunar_lambert_L", "reflectance"]

REFLECTANCE_MODELS = ("lommel-seeliger", "lunar-lambert", "lambert", "uniform")
LUNAR_LAMBERT_MCEWEN = (-0.019, 2.42e-4, -1.46e-6)


def lunar_lambert_L(alpha_rad: np.ndarray, coeffs: tuple[float, float, float] = LUNAR_LAMBERT_MCEWEN) -> np.ndarray:
    """McEwen's limb-darkening weight ``L(alpha)`` (cubic in degrees, clipped to [0, 1])."""
    a = np.degrees(np.asarray(alpha_rad, dtype=float))
    A, B, C = coeffs
    return np.clip(1.0 + A * a + B * a**2 + C * a**3, 0.0, 1.0)


def reflectance(
    model: str,
    mu0: np.ndarray,
    mu: np.ndarray,
    alpha_rad: np.ndarray | float,
    coeffs: tuple[float, float, float] = LUNAR_LAMBERT_MCEWEN,
) -> np.ndarray:
    """Radiance factor of ``model`` (module docstring) for arrays of ``mu0``, ``mu``, ``alpha``."""
    mu0 = np.asarray(mu0, dtype=float)
    mu = np.clip(np.asarray(mu, dtype=float), 0.0, 1.0)
    if model == "uniform":
        return np.ones(np.broadcast_shapes(mu0.shape, mu.shape))
    m0 = np.clip(mu0, 0.0, 1.0)
    if model == "lambert":
        return m0
    denom = m0 + mu
    with np.errstate(invalid="ignore", divide="ignore"):
        ls = np.where(denom > 0, 2.0 * m0 / np.where(denom > 0, denom, 1.0), 0.0)
    if model == "lommel-seeliger":
        return ls
    if model == "lunar-lambert":
        L = lunar_lambert_L(alpha_rad, coeffs)
        return L * ls + (1.0 - L) * m0
    raise ConfigError(f"`reflectance` must be one of {list(REFLECTANCE_MODELS)}, got {model!r}")
