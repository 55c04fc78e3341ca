r"""The glow of a thin shell above the limb (:mod:`jaxlimb.models.lunar_lambert`'s ``glow``): its radiance at a depth
inside the limb and its blurred radiance above it, with their partial derivatives.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from .profile_params import GlowProfileParams

_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)


def _erfcx(x):
    """``exp(x^2) erfc(x)`` (``jax.scipy.special.erfcx``), finite for any real ``x``."""
    return jax.scipy.special.erfcx(x)


def glow_inside(p: GlowProfileParams, v, node: bool = False):
    r"""The glow's radiance (units of ``amp``) at depth ``u = v^2`` inside the limb and its ``log_h`` derivative.

    An optically thin shell whose emission falls as :math:`e^{-h/H}` with the altitude ``h`` (the glow of
    :mod:`jaxlimb.render.independent.optics`, a dust or exosphere horizon glow): seen on the disc at depth ``u``
    below the limb the ray leaves the surface at the emission cosine :math:`\mu = \sqrt{2u/R}` and climbs
    :math:`h \approx \mu t + t^2/2R` along its length ``t``; its column over the grazing column
    :math:`\sqrt{2\pi R H}` (which sets ``glow``) is, with :math:`x = \sqrt{u/H}` (Chapman 1931's grazing
    integral, the half of a ray in front of the surface),

    .. math:: \frac{1}{\sqrt{2\pi RH}}\int_0^\infty e^{-(\mu t + t^2/2R)/H}\,dt = \tfrac12\,\mathrm{erfcx}(x),

    1/2 at the limb, :math:`\sqrt{H/4\pi u}` deep inside.  ``d erfcx(x)/dx = 2x erfcx(x) - 2/sqrt(pi)``,
    ``dx/dlog_h = -x/2``; with ``node``, also the derivative in ``v`` (``dx/dv = x / v``).

    Parameters
    ----------
    p : GlowProfileParams
        Supplies ``log_h``, the log of the glow's scale height (px).
    v : jax.Array
        Square root of the depth below the limb (px^1/2).
    node : bool
        Also return the derivative in ``v``.

    Returns
    -------
    tuple of jax.Array
        ``(G, G_lh)`` or, with ``node``, ``(G, G_lh, G_v)``: the radiance per unit ``glow`` and its partials in
        ``log_h`` and ``v``, shape of ``v``.
    """
    x = v * jnp.exp(-0.5 * p.log_h)
    ex = _erfcx(x)
    G = 0.5 * ex
    G_lh = -0.5 * x * (x * ex - _INV_SQRT_PI)
    if not node:
        return G, G_lh
    return G, G_lh, (x * ex - _INV_SQRT_PI) * jnp.exp(-0.5 * p.log_h)


def glow_outside(p: GlowProfileParams, s, se, d, derivatives: bool):
    r"""The blurred glow above the limb (units of ``amp`` per unit ``glow``) at signed distance ``s = d - R``
    (px, positive outside) and, if asked, its partials in ``d``, ``R``, ``se`` and ``log_h``.

    The radiance :math:`e^{-s'/H}` for :math:`s' > 0` (the miss column of the shell,
    :math:`2p K_1(p/H) e^{p/H} e^{-(p-R)/H}`, over the grazing one, to :math:`O(s/R)`) convolved with the
    Gaussian :math:`N(\cdot;\sigma_e)`: completing the square,

    .. math:: E(s) = \int_0^\infty e^{-t/H} N(s - t)\,dt = e^{\sigma_e^2/2H^2 - s/H}\,
              \Phi\big(s/\sigma_e - \sigma_e/H\big),

    evaluated as ``exp(a - s/H + log Phi(w))`` (no overflow for ``H << se``).  Derivatives in closed form:
    :math:`E' = N - E/H`, :math:`E'' = N' - E'/H` (``N' = -s N / se^2``), :math:`\partial_{\sigma_e} E = \sigma_e E''`
    (the heat equation), :math:`H\,\partial_H E = (s E + \sigma_e^2 E')/H`.  As the profile
    (:func:`jaxlimb.models.lunar_lambert.profile_integrals`), the 2-D blur adds the curvature term :math:`\sigma_e^2/(2d)\,E'`.

    Parameters
    ----------
    p : GlowProfileParams
        Supplies ``log_h``, the log of the glow's scale height (px).
    s : jax.Array (n,)
        Signed distance above the limb, ``d - R`` (px).
    se : jax.Array
        Blur sigma :math:`\sigma_e` (px), one for all pixels or ``(n,)``.
    d : jax.Array (n,)
        Distance of each pixel from the centre (px), for the curvature term.
    derivatives : bool
        Also return the partials.

    Returns
    -------
    G : jax.Array (n,)
        The blurred glow with its curvature term.
    parts : dict of str to jax.Array (n,), or None
        With ``derivatives``: ``G_d``, ``G_R``, ``G_se``, ``G_lh``, the partials in ``d``, ``R``, ``se`` and
        ``log_h``; ``None`` otherwise.
    """
    H = jnp.exp(p.log_h)
    inv_H = 1.0 / H
    w = s / se - se * inv_H
    E = jnp.exp(0.5 * (se * inv_H) ** 2 - s * inv_H + jax.scipy.special.log_ndtr(w))
    N = jnp.exp(-0.5 * (s / se) ** 2) / (se * math.sqrt(2.0 * math.pi))
    E1 = N - E * inv_H
    k = se * se / (2.0 * d)
    G = E + k * E1
    if not derivatives:
        return G, None
    N1 = -s / (se * se) * N
    N2 = (s * s / se**4 - 1.0 / (se * se)) * N
    E2 = N1 - E1 * inv_H
    E3 = N2 - E2 * inv_H
    E_lh = (s * E + se * se * E1) * inv_H
    E1_lh = (E + s * E1 + se * se * E2) * inv_H  # d/ds of E_lh
    parts = {
        "G_d": E1 + k * (E2 - E1 / d),
        "G_R": -(E1 + k * E2),
        "G_se": se * E2 + k * se * E3 + se / d * E1,
        "G_lh": E_lh + k * E1_lh,
    }
    return G, parts
