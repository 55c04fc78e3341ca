r"""The limb of the Sun in the extreme ultraviolet: an optically thin corona over an opaque disc.

Why.  At EUV wavelengths (SDO/AIA 171-335 A, SOHO/EIT, STEREO/EUVI, PROBA2/SWAP, Solar Orbiter/FSI) the
photosphere is dark and the image is the emission of the hot corona, optically thin, above an opaque lower
atmosphere.  The disc's edge is where that occulting surface hides the back half of each line of sight: the
brightness *doubles* across it, peaks just above it and falls off with the corona's scale height.  A limb-darkened
disc (:mod:`jaxlimb.models.limb_darkened`) or a sigmoid fits the outer fall-off instead, several pixels outside.

Radiance.  Emissivity :math:`\epsilon_0 e^{-(\rho - a)/h}` at heights :math:`\rho - a \ge 0` above the occulting
radius ``a``; the column at impact parameter ``r = a + x`` with ``a >> h, |x|`` (a line of sight near the limb
passes the layer along :math:`ds = \sqrt{a / (2(y - x))}\,dy`, ``y`` its height):

.. math:: C(x) \propto e^{-x/h} \quad (x \ge 0), \qquad
          C(x) \propto \tfrac12\,\mathrm{erfcx}\!\left(\sqrt{-x/h}\right) \quad (x < 0)

(both sides of the line of sight above the limb, only the front side on the disc: the factor 2 across ``x = 0``),
plus a uniform disc level for the lower-lying emission seen on the disc.  Chapman 1931 (Proc. Phys. Soc. 43, 483)
for the grazing column of an exponential atmosphere; Aschwanden 2005, *Physics of the Solar Corona*, sec. 3.1
(hydrostatic scale heights, the EUV limb brightening).

Blur.  A Gaussian PSF with the pixel's box, :math:`\sigma_e^2 = \sigma^2 + 1/12`, along the radius (1-D:
``a >> sigma``).  Above the limb the blur is closed form,

.. math:: (e^{-x'/h}\,[x' \ge 0]) * N_{\sigma_e} = \exp\!\left(-\frac{x}{h} + \frac{\sigma_e^2}{2h^2}\right)
          \Phi\!\left(\frac{x}{\sigma_e} - \frac{\sigma_e}{h}\right),

and the disc level is :math:`\Phi(-x/\sigma_e)`.  The on-disc column is integrated with the depth :math:`-x' = v^2`
(no square-root behaviour at the limb) by an :data:`N_NODES`-point Gauss-Legendre rule on
:math:`v_{0,1} = \sqrt{\max(0, -x \mp 6\sigma_e)}`.  The intensity at a pixel a distance ``d`` from ``(r0, c0)``:

.. math:: f = y_{\min} + A\,[S_\mathrm{above}(x) + S_\mathrm{disc}(x)] + D\,\Phi(-x/\sigma_e), \qquad x = d - a.

Parameters ``(r0, c0, a, sigma, log_h, amp, disc, ymin)``: centre (px), occulting radius (px, the top of the
chromosphere: a few Mm above the photosphere), PSF sigma (px), log of the scale height (px), the corona's
brightness just above the limb, the disc level, the sky.  The Jacobian (:func:`_value_and_columns`) is the
derivative of the rule as computed: the integrand at fixed nodes plus the move of the nodes with the window's ends.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfcx, log_ndtr, ndtr
from jaxtyping import ArrayLike

from ._base import LimbParams, fused_model

#: Gauss-Legendre nodes of the on-disc column's blur integral (module docstring).
N_NODES = 24
_GL_X, _GL_W = np.polynomial.legendre.leggauss(N_NODES)
_SQRT_2PI = math.sqrt(2.0 * math.pi)
_SQRT_PI = math.sqrt(math.pi)
#: Half-width of the blur window in PSF sigmas.
_WINDOW = 6.0


class CoronaParams(LimbParams):
    """Parameters of :func:`corona_intensity` (module docstring).

    ``r0, c0`` disc centre (px, ``(row, col)``); ``a`` occulting radius (px); ``sigma`` Gaussian PSF (px, the pixel
    box is added); ``log_h`` log of the corona's scale height (px); ``amp`` its brightness just above the limb;
    ``disc`` the uniform disc level; ``ymin`` the sky.
    """

    r0: ArrayLike
    c0: ArrayLike
    a: ArrayLike
    sigma: ArrayLike
    log_h: ArrayLike
    amp: ArrayLike
    disc: ArrayLike
    ymin: ArrayLike


def _gauss(u):
    return jnp.exp(-0.5 * u * u) / _SQRT_2PI


def _above(x, se, h):
    """The blurred column above the limb and its derivatives in ``(x, se, h)`` (closed form, module docstring)."""
    z = x / se - se / h
    s = jnp.exp(-x / h + 0.5 * (se / h) ** 2 + log_ndtr(z))
    g = _gauss(x / se)  # = exp(-x/h + se^2/2h^2) phi(z): the exponents cancel
    return s, -s / h + g / se, s * se / (h * h) - g * (x / (se * se) + 1.0 / h), s * (x / (h * h) - se * se / h ** 3) \
        + g * se / (h * h)


def _window(x, se):
    """Ends ``v0, v1`` of the on-disc window and their derivatives in ``x`` and ``se``."""
    out = []
    for sign in (-1.0, 1.0):
        w = -x + sign * _WINDOW * se
        on = w > 1e-12
        v = jnp.sqrt(jnp.where(on, w, 1e-12))
        dv = jnp.where(on, 0.5 / v, 0.0)
        out.append((v, -dv, sign * _WINDOW * dv))
    return out


def _disc_column(x, se, h):
    """The blurred on-disc column ``S_disc`` and its derivatives in ``(x, se, h)``: the rule as computed."""
    (v0, v0x, v0s), (v1, v1x, v1s) = _window(x, se)
    half = 0.5 * (v1 - v0)
    xi = jnp.asarray(_GL_X)
    v = v0[..., None] + half[..., None] * (xi + 1.0)
    sh = jnp.sqrt(h)
    y = v / sh
    e = erfcx(y)
    e_y = 2.0 * y * e - 2.0 / _SQRT_PI
    u = (x[..., None] + v * v) / se[..., None]
    G = _gauss(u) / se[..., None]
    hv = e * G * v  # the integrand: (1/2) erfcx * N * 2v
    hv_v = e_y / sh * G * v + e * G * (1.0 - u * 2.0 * v * v / se[..., None])
    hv_x = -e * G * v * u / se[..., None]
    hv_s = e * G * v * (u * u - 1.0) / se[..., None]
    hv_h = e_y * (-0.5 * y / h) * G * v
    w = jnp.asarray(_GL_W)
    S = half * jnp.sum(w * hv, -1)

    def ends(d0, d1):  # the move of the nodes with the window's ends
        dv = d0[..., None] * (1.0 - xi) / 2.0 + d1[..., None] * (1.0 + xi) / 2.0
        return 0.5 * (d1 - d0) * jnp.sum(w * hv, -1) + half * jnp.sum(w * hv_v * dv, -1)

    return (S, half * jnp.sum(w * hv_x, -1) + ends(v0x, v1x), half * jnp.sum(w * hv_s, -1) + ends(v0s, v1s),
            half * jnp.sum(w * hv_h, -1))


def _distance(p: CoronaParams, rc):
    rc = jnp.asarray(rc)
    dr = rc[..., 0] - p.r0
    dc = rc[..., 1] - p.c0
    d2 = dr * dr + dc * dc
    return jnp.sqrt(jnp.where(d2 > 0, d2, 1.0)), dr, dc


def _value_and_columns(p: CoronaParams, rc):
    """Intensity and the 8 Jacobian columns (field order) in one pass (module docstring)."""
    d, dr, dc = _distance(p, rc)
    x = d - p.a
    se = jnp.sqrt(p.sigma * p.sigma + 1.0 / 12.0) * jnp.ones_like(x)
    h = jnp.exp(p.log_h)
    a_s, a_x, a_se, a_h = _above(x, se, h)
    d_s, d_x, d_se, d_h = _disc_column(x, se, h)
    step = ndtr(-x / se)
    g = _gauss(x / se)
    col = a_s + d_s
    f_x = p.amp * (a_x + d_x) - p.disc * g / se
    f_se = p.amp * (a_se + d_se) + p.disc * g * x / (se * se)
    inv_d = 1.0 / d
    cols = (-f_x * dr * inv_d, -f_x * dc * inv_d, -f_x, f_se * p.sigma / se, p.amp * (a_h + d_h) * h, col, step,
            jnp.ones_like(x))
    return p.ymin + p.amp * col + p.disc * step, cols


def corona_intensity(p: CoronaParams, rc):
    """The blurred EUV limb (module docstring) at pixels ``rc`` ``(n, 2)`` as ``(row, col)``.

    Parameters
    ----------
    p : CoronaParams
        Centre, occulting radius, PSF, scale height, corona and disc levels, sky.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,)
        Model intensity at each pixel.
    """
    return _value_and_columns(p, rc)[0]


CORONA = fused_model("corona", CoronaParams, corona_intensity, _value_and_columns)
"""The EUV limb model (module docstring), with its analytic Jacobian."""


__all__ = ["CORONA", "CoronaParams", "corona_intensity"]
