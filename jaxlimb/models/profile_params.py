"""The parameters of the physical limb profiles (:mod:`jaxlimb.models.lunar_lambert`): the lunar-Lambert profile and
its widened variants (Minnaert-like brightening, a glow above the limb, an anisotropic blur), the held set and
McEwen's lunar-Lambert weight."""

from __future__ import annotations

import math

from jaxtyping import ArrayLike

from ._base import LimbParams

PROFILE_FIXED = ("theta", "rho", "sun_r", "sun_c", "phase", "inv_f", "L", "L_slope", "L_ref")


class LimbProfileParams(LimbParams):
    """Parameters of :func:`jaxlimb.models.lunar_lambert.limb_profile_intensity` (its module docstring).

    ``r0, c0, a, theta, rho`` are the limb ellipse as in :class:`jaxlimb.models.EllipseParams`
    (``rho = 1``: a circle of radius ``a``); ``sigma`` the Gaussian PSF (px); ``amp``, ``ymin``
    the radiance scale and the sky level; ``sun_r, sun_c, phase, inv_f`` fixed geometry; ``L`` the lunar-Lambert
    weight at the body centre's phase angle; ``L_ref`` and ``L_slope`` McEwen's weight there and its relative
    derivative in the phase angle, ``d ln L / d phase`` (1/rad), which set the weight at each point of the disc
    (:mod:`jaxlimb.models.lunar_lambert`, "The phase angle across the disc").
    """

    r0: ArrayLike
    c0: ArrayLike
    a: ArrayLike
    theta: ArrayLike
    rho: ArrayLike
    sigma: ArrayLike
    amp: ArrayLike
    ymin: ArrayLike
    sun_r: ArrayLike
    sun_c: ArrayLike
    phase: ArrayLike
    inv_f: ArrayLike
    L: ArrayLike
    L_slope: ArrayLike
    L_ref: ArrayLike


class MinnaertProfileParams(LimbProfileParams):
    """:class:`LimbProfileParams` and ``kappa``, the limb-brightening exponent of
    :data:`LIMB_PROFILE_MINNAERT`: the lunar-Lambert radiance times ``(mu0 mu)^-kappa`` (at ``L = 0``
    Minnaert's law ``mu0^k mu^(k-1)``, Minnaert 1941, with ``k = 1 - kappa``)."""

    kappa: ArrayLike


class GlowProfileParams(LimbProfileParams):
    """:class:`LimbProfileParams` and an exponential glow above the limb (:data:`LIMB_PROFILE_GLOW`):
    ``glow``, its radiance just above the limb in units of ``amp`` where the limb's normal is square to the Sun's
    image direction, ``log_h``, the log of its scale height (px), and ``glow_tilt``, its linear change with the
    cosine ``cpsi`` of the angle between the limb's normal and the Sun's image direction: the glow's radiance is
    ``glow (1 + glow_tilt cpsi)`` (module docstring)."""

    glow: ArrayLike
    log_h: ArrayLike
    glow_tilt: ArrayLike = 0.0


class AnisoProfileParams(LimbProfileParams):
    """:class:`LimbProfileParams` and an anisotropic blur (:data:`LIMB_PROFILE_ANISO`): ``s2c, s2s`` (px^2), the
    cos 2psi and sin 2psi terms of the blur variance across the limb, ``sigma_e^2(psi) = sigma^2 + 1/12 + s2c cos 2psi
    + s2s sin 2psi`` with ``psi`` the angle of the ray from the centre (the limb normal's, from ``+col`` toward
    ``-row``).  A line smear of length ``l`` at angle ``phi`` adds ``l^2/12 cos^2(psi - phi)`` to a Gaussian's
    variance across an edge: ``l^2/24 (1 + cos 2(psi - phi))``, the mean in ``sigma^2``, the rest in ``s2c, s2s``."""

    s2c: ArrayLike
    s2s: ArrayLike


PHYSICAL_L = (-0.1, 1.1)
"""Lunar-Lambert weights ``L`` a fitted profile may take under ``profile="auto"``: ``[0, 1]`` with a
margin, widened by 3 of the fit's own sigma of ``L`` (a 33 px Moon with 10 DN of noise fits a
Lommel-Seeliger limb, ``L = 1``, at 1.13 now and then)."""


MCEWEN_LUNAR_LAMBERT = (-0.019, 2.42e-4, -1.46e-6)
"""McEwen's cubic ``(A, B, C)`` of the Moon's lunar-Lambert weight in the phase angle (degrees)."""


def _mcewen_cubic(phase_rad: float, coeffs) -> tuple[float, float]:
    """``1 + A a + B a^2 + C a^3`` (``a`` the phase angle in degrees, unclipped) and its derivative (1/rad)."""
    a = math.degrees(phase_rad)
    A, B, C = coeffs
    return 1.0 + A * a + B * a * a + C * a**3, (A + 2.0 * B * a + 3.0 * C * a * a) * 180.0 / math.pi


def lunar_lambert_weight(phase_rad: float, coeffs=MCEWEN_LUNAR_LAMBERT) -> float:
    """McEwen's lunar-Lambert weight ``L(alpha) = 1 + A alpha + B alpha^2 + C alpha^3`` (alpha in degrees).

    Parameters
    ----------
    phase_rad : float
        Phase angle (rad).
    coeffs : tuple of float
        ``(A, B, C)`` of the cubic in degrees; the default is McEwen's fit for the Moon.

    Returns
    -------
    float
        ``L``, clipped to ``[0, 1]``.
    """
    return float(min(1.0, max(0.0, _mcewen_cubic(phase_rad, coeffs)[0])))


def lunar_lambert_slope(phase_rad: float, coeffs=MCEWEN_LUNAR_LAMBERT) -> float:
    """``d ln L / d alpha`` (1/rad) of :func:`lunar_lambert_weight`: ``(A + 2 B alpha + 3 C alpha^2) 180/pi / L``, 0
    where the weight is clipped to 0 or 1.

    Parameters
    ----------
    phase_rad : float
        Phase angle (rad).
    coeffs : tuple of float
        ``(A, B, C)`` as in :func:`lunar_lambert_weight`.

    Returns
    -------
    float
        The weight's relative derivative in the phase angle (1/rad).
    """
    L, dL = _mcewen_cubic(phase_rad, coeffs)
    return float(dL / L) if 0.0 < L < 1.0 else 0.0


def glow_fields(p: LimbProfileParams) -> dict[str, float]:
    """The glow of a :class:`GlowProfileParams` fit for a report: ``glow`` (units of ``amp``) and
    ``glow_scale_px`` (its scale height); ``glow = 0`` for the other profiles.

    Parameters
    ----------
    p : LimbProfileParams
        A fitted profile of any variant.

    Returns
    -------
    dict of str to float
        ``{"glow": 0.0}``, or ``glow``, ``glow_scale_px`` and ``glow_tilt`` for a glow fit.
    """
    if not isinstance(p, GlowProfileParams):
        return {"glow": 0.0}
    return {"glow": float(p.glow), "glow_scale_px": math.exp(float(p.log_h)), "glow_tilt": float(p.glow_tilt)}


__all__ = ["PHYSICAL_L", "PROFILE_FIXED", "AnisoProfileParams", "GlowProfileParams", "LimbProfileParams",
           "MCEWEN_LUNAR_LAMBERT", "MinnaertProfileParams", "glow_fields", "lunar_lambert_slope", "lunar_lambert_weight"]
