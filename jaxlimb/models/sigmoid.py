r"""Linear, circular and elliptical sigmoid limb models and their analytic Jacobians.

Section V of Mortari, D'Souza & Zanetti, *Image Processing of Illuminated
Ellipsoid* [1]_: the smooth bright-to-dark transition across a limb is modelled
by a logistic function of a signed distance to the limb,

.. math::  f = y_{\max} + \frac{y_{\min} - y_{\max}}{1 + \alpha},
           \qquad \alpha = e^{k (\text{limb} - \text{distance})},

so that ``f -> ymax`` inside the body and ``f -> ymin`` outside.  Each model
comes with the paper's analytic Jacobian written separately, directly below it;
the tests check each against ``jax.jacfwd`` and against central differences.

Numerical form
--------------
The paper writes the derivatives with :math:`\alpha/(1+\alpha)^2` and
:math:`\alpha/(1+\alpha)`.  For steep ``k`` or pixels far from the limb,
:math:`\alpha` overflows and the literal expressions give ``inf/inf = nan``.
We evaluate the *same* expressions through :math:`s = 1/(1+\alpha) =
\operatorname{sigmoid}(k(\text{distance} - \text{limb}))` and
:math:`\bar s = \alpha/(1+\alpha) = \operatorname{sigmoid}(-k(\ldots))`
(computed directly, not as ``1 - s``, which would lose the tail's relative
precision), so :math:`\alpha/(1+\alpha)^2 = s\bar s`.  These are identities,
not approximations.

All functions are pure, jit-compatible and vectorised over pixels; run them in
float64 (``jax.config.update("jax_enable_x64", True)``).

References
----------
.. [1] D. Mortari, C. N. D'Souza, R. Zanetti, "Image Processing of Illuminated
   Ellipsoid", Journal of Spacecraft and Rockets 53(3), 2016,
   doi:10.2514/1.A33342.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import LimbModel, LimbParams


@jax.custom_jvp
def _pair(z: Array) -> tuple[Array, Array]:
    """``(sigmoid(z), sigmoid(-z))`` = ``(1/(1+alpha), alpha/(1+alpha))`` from one ``exp``, without overflow.

    Both are computed directly (``sigmoid(-z)`` is not ``1 - sigmoid(z)``, which
    would lose all relative precision in the tail).  The derivative is
    ``d sigmoid(z) = sigmoid(z) sigmoid(-z) dz``; JAX's own rule for
    ``lax.logistic`` computes ``s (1 - s)``, which would make autodiff
    Jacobians wrong by up to ~1e-7 relative in the tails, where the paper's
    formulas are exact to rounding.
    """
    e = jnp.exp(-jnp.abs(z))
    big = 1.0 / (1.0 + e)
    small = e * big
    pos = z >= 0
    return jnp.where(pos, big, small), jnp.where(pos, small, big)


@_pair.defjvp
def _pair_jvp(primals, tangents):  # type: ignore[no-untyped-def]
    (z,), (dz,) = primals, tangents
    s, sc = _pair(z)
    d = s * sc * dz
    return (s, sc), (d, -d)


def _levels(p: "LimbParams", z: Array) -> Array:
    """``ymax + (ymin - ymax) / (1 + alpha)`` written as ``ymax * alpha/(1+alpha) + ymin / (1+alpha)``.

    Same value; but every derivative, including ``d/dymax = alpha/(1+alpha)``,
    then keeps full relative precision under autodiff.
    """
    s, sc = _pair(z)
    return p.ymax * sc + p.ymin * s


def _safe_norm(a: Array, b: Array) -> Array:
    """``sqrt(a^2 + b^2)`` with a finite (zero) gradient at the origin."""
    sq = a * a + b * b
    pos = sq > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, sq, 1.0)), 0.0)


# =============================================================================== linear
class LinearParams(LimbParams):
    """Parameters of the linear sigmoid function, Eq. (12) of [1]_ (Jacobian column order).

    Attributes
    ----------
    xt : where the transition occurs (the 50 % point).
    k : steepness of the transition (> 0; larger is sharper).
    ymax, ymin : the levels for ``x -> -inf`` and ``x -> +inf``.
    """

    xt: ArrayLike
    k: ArrayLike
    ymax: ArrayLike
    ymin: ArrayLike


def linear_intensity(p: LinearParams, x: Float[Array, " n"]) -> Float[Array, " n"]:
    r"""Linear sigmoid function (LSF), Eq. (12) of [1]_.

    .. math:: f = y_{\max} + \frac{y_{\min} - y_{\max}}{1 + e^{k (x_t - x)}}

    Parameters
    ----------
    p : LinearParams
        Transition point ``xt``, steepness ``k`` and the levels ``ymax`` (``x -> -inf``), ``ymin`` (``x -> +inf``).
    x : jax.Array (n,)
        Positions along the line (px), e.g. the samples of a scan line across the limb.

    Returns
    -------
    jax.Array (n,)
        Model intensity at each position.

    Examples
    --------
    >>> import numpy as np
    >>> from jaxlimb.models import LinearParams, linear_intensity
    >>> p = LinearParams(xt=50.0, k=0.5, ymax=150.0, ymin=20.0)
    >>> np.round(np.asarray(linear_intensity(p, np.array([40.0, 50.0, 60.0])), dtype=float), 2)
    array([149.13,  85.  ,  20.87])
    """
    x = jnp.asarray(x)
    z = p.k * (x - p.xt)
    return _levels(p, z)


def linear_intensity_jac(p: LinearParams, x: Float[Array, " n"]) -> Float[Array, "n 4"]:
    r"""Analytic Jacobian of the LSF, Eq. (13)-(14) of [1]_; columns ``(xt, k, ymax, ymin)``.

    With :math:`\alpha_i = e^{k(x_t - x_i)}` (Eq. 13):
    :math:`\partial f/\partial y_{\min} = 1/(1+\alpha)`,
    :math:`\partial f/\partial y_{\max} = \alpha/(1+\alpha)`,
    :math:`\partial f/\partial x_t = -(y_{\min}-y_{\max})\,\alpha k/(1+\alpha)^2`,
    :math:`\partial f/\partial k = (x_t - x_i)/k \cdot \partial f/\partial x_t`.

    Parameters
    ----------
    p : LinearParams
        The point at which to differentiate.
    x : jax.Array (n,)
        Positions along the line (px).

    Returns
    -------
    jax.Array (n, 4)
        :math:`\partial f_i/\partial(x_t, k, y_{\max}, y_{\min})`, columns in the field order of ``p``.
    """
    return jnp.stack(_linear_jac_columns(p, x), axis=-1)


def _linear_jac_columns(p: LinearParams, x: Float[Array, " n"]) -> tuple[Array, ...]:
    """Columns of :func:`linear_intensity_jac` (stacked by the caller in the layout it needs)."""
    return _linear_value_and_columns(p, x)[1]


def _linear_value_and_columns(p: LinearParams, x: Float[Array, " n"]) -> tuple[Array, tuple[Array, ...]]:
    """Intensity (Eq. 12) and Jacobian columns (Eq. 14) from one pass over the pixels."""
    x = jnp.asarray(x)
    z = p.k * (x - p.xt)
    s, sc = _pair(z)  # 1/(1+alpha), alpha/(1+alpha)
    a_1a2 = s * sc  # alpha/(1+alpha)^2
    dy = p.ymin - p.ymax
    d_xt = -dy * a_1a2 * p.k
    d_k = -dy * a_1a2 * (p.xt - x)  # == (xt - x)/k * d_xt, written without the division by k
    return p.ymax * sc + p.ymin * s, (d_xt, d_k, sc, s)


# =============================================================================== circle
class CircleParams(LimbParams):
    """Parameters of the circular sigmoid function, Eq. (16) of [1]_ (Jacobian column order).

    Attributes
    ----------
    r0, c0 : centre of the circle, pixels ``(row, col)``.
    radius : the radius :math:`r_e` where the transition occurs (px, > 0).
    k : steepness (1/px, > 0).
    ymax, ymin : inside (body) and outside (sky) levels.
    """

    r0: ArrayLike
    c0: ArrayLike
    radius: ArrayLike
    k: ArrayLike
    ymax: ArrayLike
    ymin: ArrayLike


def circle_intensity(p: CircleParams, rc: Float[Array, "n 2"]) -> Float[Array, " n"]:
    r"""Circular sigmoid function (CSF), Eq. (16) of [1]_.

    .. math:: f = y_{\max} + \frac{y_{\min} - y_{\max}}{1 + e^{k(r_e - d)}},
              \quad d = \sqrt{(c_0 - c)^2 + (r_0 - r)^2}

    Parameters
    ----------
    p : CircleParams
        Centre ``(r0, c0)`` (px), radius :math:`r_e` (px), steepness ``k`` (1/px) and the inside (``ymax``) and
        outside (``ymin``) levels.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,)
        Model intensity at each pixel.

    Examples
    --------
    A disc of radius 30 px: its centre is at ``ymax``, its limb halfway between the levels.

    >>> import numpy as np
    >>> from jaxlimb.models import CircleParams, circle_intensity
    >>> p = CircleParams(r0=100.0, c0=120.0, radius=30.0, k=2.0, ymax=200.0, ymin=10.0)
    >>> rc = np.array([[100.0, 120.0], [100.0, 150.0], [100.0, 151.0]])
    >>> np.round(np.asarray(circle_intensity(p, rc), dtype=float), 2)
    array([200.  , 105.  ,  32.65])
    """
    rc = jnp.asarray(rc)
    d = _safe_norm(p.r0 - rc[..., 0], p.c0 - rc[..., 1])
    return _levels(p, p.k * (d - p.radius))


def circle_intensity_jac(p: CircleParams, rc: Float[Array, "n 2"]) -> Float[Array, "n 6"]:
    r"""Analytic Jacobian of the CSF, Eq. (17) of [1]_; columns ``(r0, c0, radius, k, ymax, ymin)``.

    With :math:`\beta_i = d_i` and :math:`\alpha_i = e^{k(r_e - \beta_i)}`:

    .. math::
        \partial f/\partial r_0 &= (y_{\min}-y_{\max})\,\alpha k/(1+\alpha)^2\,(r_0 - r_i)/\beta_i \\
        \partial f/\partial c_0 &= (y_{\min}-y_{\max})\,\alpha k/(1+\alpha)^2\,(c_0 - c_i)/\beta_i \\
        \partial f/\partial r_e &= -(y_{\min}-y_{\max})\,\alpha k/(1+\alpha)^2 \\
        \partial f/\partial k &= -(y_{\min}-y_{\max})\,\alpha/(1+\alpha)^2\,(r_e - \beta_i) \\
        \partial f/\partial y_{\max} &= \alpha/(1+\alpha), \qquad
        \partial f/\partial y_{\min} = 1/(1+\alpha)

    At the centre (:math:`\beta_i = 0`) the direction is undefined; the centre
    columns are set to 0 there (autodiff of :func:`circle_intensity` agrees).

    Parameters
    ----------
    p : CircleParams
        The point at which to differentiate.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n, 6)
        :math:`\partial f_i/\partial(r_0, c_0, r_e, k, y_{\max}, y_{\min})`, columns in the field order of ``p``.
    """
    return jnp.stack(_circle_jac_columns(p, rc), axis=-1)


def _circle_jac_columns(p: CircleParams, rc: Float[Array, "n 2"]) -> tuple[Array, ...]:
    """Columns of :func:`circle_intensity_jac` (stacked by the caller in the layout it needs)."""
    return _circle_value_and_columns(p, rc)[1]


def _circle_value_and_columns(p: CircleParams, rc: Float[Array, "n 2"]) -> tuple[Array, tuple[Array, ...]]:
    """Intensity (Eq. 16) and Jacobian columns (Eq. 17) from one pass over the pixels."""
    rc = jnp.asarray(rc)
    dr = p.r0 - rc[..., 0]
    dc = p.c0 - rc[..., 1]
    beta = _safe_norm(dr, dc)
    z = p.k * (beta - p.radius)
    s, sc = _pair(z)  # 1/(1+alpha), alpha/(1+alpha)
    g = (p.ymin - p.ymax) * s * sc  # (ymin - ymax) alpha / (1 + alpha)^2
    inv_beta = jnp.where(beta > 0, 1.0 / jnp.where(beta > 0, beta, 1.0), 0.0)
    d_r0 = g * p.k * dr * inv_beta
    d_c0 = g * p.k * dc * inv_beta
    d_re = -g * p.k
    d_k = -g * (p.radius - beta)
    return p.ymax * sc + p.ymin * s, (d_r0, d_c0, d_re, d_k, sc, s)


# =============================================================================== ellipse
class EllipseParams(LimbParams):
    r"""Parameters of the elliptical sigmoid function, Sec. V-C of [1]_ (Jacobian column order).

    Attributes
    ----------
    r0, c0 : centre of the ellipse, pixels ``(row, col)``.
    a : semi-axis along the ellipse's own ``x`` axis (px, > 0).
    theta : orientation :math:`\vartheta` (rad) of the ``x`` axis, see :func:`ellipse_coords`.
    rho : axis ratio :math:`\rho = b/a` (Eq. 9); usually held fixed from the geometry.
    k : steepness (> 0), ymax / ymin : inside and outside levels.
    """

    r0: ArrayLike
    c0: ArrayLike
    a: ArrayLike
    theta: ArrayLike
    rho: ArrayLike
    k: ArrayLike
    ymax: ArrayLike
    ymin: ArrayLike


def ellipse_coords(p: EllipseParams, rc: Float[Array, "n 2"]) -> tuple[Array, Array]:
    r"""Pixel ``(r, c)`` -> ellipse frame ``(x, y)``: the transform of the missing Appendix A of [1]_.

    Derivation.  The paper gives :math:`\partial f/\partial r_0`,
    :math:`\partial f/\partial c_0` and :math:`\partial f/\partial\vartheta` but
    not the transform (its Eq. 19-20 are in an appendix that was not printed).
    With :math:`\beta = \sqrt{\rho^2 x^2 + y^2}` and
    :math:`\partial f/\partial\beta = (y_{\min}-y_{\max})\alpha k/(1+\alpha)^2`,
    the chain rule gives
    :math:`\partial f/\partial q = (\ldots)\,k\,(\rho^2 x\,\partial x/\partial q
    + y\,\partial y/\partial q)/\beta`.  Matching the paper's three formulas
    term by term requires

    .. math::
        \partial x/\partial r_0 = \sin\vartheta,\quad
        \partial x/\partial c_0 = -\cos\vartheta,\quad
        \partial y/\partial r_0 = \cos\vartheta,\quad
        \partial y/\partial c_0 = \sin\vartheta,\quad
        \partial x/\partial\vartheta = y,\quad
        \partial y/\partial\vartheta = -x .

    The transform is affine in :math:`(r_0, c_0)` and vanishes at the centre,
    so the first four fix it uniquely (Eq. 19):

    .. math::
        x &= (c - c_0)\cos\vartheta - (r - r_0)\sin\vartheta \\
        y &= -(r - r_0)\cos\vartheta - (c - c_0)\sin\vartheta

    and the last two then hold identically, confirming the paper's
    :math:`\partial f/\partial\vartheta`.  The inverse (Eq. 20) is
    :math:`c = c_0 + x\cos\vartheta - y\sin\vartheta`,
    :math:`r = r_0 - x\sin\vartheta - y\cos\vartheta`.

    Geometrically, ``x`` points along ``(row, col) = (-sin t, cos t)`` and
    ``y`` along ``(-cos t, -sin t)``: on the image as displayed (row down),
    :math:`\vartheta` turns the ``x`` axis counter-clockwise from ``+col``,
    and ``y`` is ``x`` turned by another 90 degrees counter-clockwise.  The
    semi-axis ``a`` lies along ``x`` and ``b = rho a`` along ``y``.

    Parameters
    ----------
    p : EllipseParams
        Centre ``(r0, c0)`` (px) and orientation ``theta`` (rad); the other fields are not used.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    x : jax.Array (n,)
        Coordinate along the ellipse's ``a`` axis (px).
    y : jax.Array (n,)
        Coordinate along its ``b`` axis (px).
    """
    rc = jnp.asarray(rc)
    dr = rc[..., 0] - p.r0
    dc = rc[..., 1] - p.c0
    ct, st = jnp.cos(p.theta), jnp.sin(p.theta)
    x = dc * ct - dr * st
    y = -dr * ct - dc * st
    return x, y


def ellipse_points(p: EllipseParams, phi: Float[Array, " m"]) -> Float[Array, "m 2"]:
    r"""Points ``(row, col)`` on the ellipse at eccentric anomalies ``phi`` (inverse transform, Eq. 20).

    Parameters
    ----------
    p : EllipseParams
        Centre ``(r0, c0)`` (px), semi-axis ``a`` (px), orientation ``theta`` (rad) and axis ratio ``rho``.
    phi : jax.Array (m,)
        Eccentric anomalies (rad), measured from the ``a`` axis toward the ``b`` axis.

    Returns
    -------
    jax.Array (m, 2)
        The points :math:`(x, y) = (a\cos\varphi, \rho a\sin\varphi)` as pixel coordinates ``(row, col)``.
    """
    x = p.a * jnp.cos(phi)
    y = p.rho * p.a * jnp.sin(phi)
    ct, st = jnp.cos(p.theta), jnp.sin(p.theta)
    return jnp.stack([p.r0 - x * st - y * ct, p.c0 + x * ct - y * st], axis=-1)


def ellipse_intensity(p: EllipseParams, rc: Float[Array, "n 2"]) -> Float[Array, " n"]:
    r"""Elliptical sigmoid function (ESF), Sec. V-C of [1]_.

    .. math:: f = y_{\max} + \frac{y_{\min} - y_{\max}}{1 + e^{k(\rho a - \beta)}},
              \quad \beta = \sqrt{\rho^2 x^2 + y^2}

    with ``(x, y)`` from :func:`ellipse_coords`.  The level set
    :math:`\beta = \rho a` is the ellipse :math:`x^2/a^2 + y^2/(\rho a)^2 = 1`
    (Eq. 18).

    Parameters
    ----------
    p : EllipseParams
        Centre ``(r0, c0)`` (px), semi-axis ``a`` (px), orientation ``theta`` (rad), axis ratio ``rho = b/a``,
        steepness ``k`` (1/px) and the inside (``ymax``) and outside (``ymin``) levels.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,)
        Model intensity at each pixel.

    Examples
    --------
    An ellipse with ``a = 40`` px along the columns (``theta = 0``) and ``b = 30`` px along the rows: both
    ends of its axes are on the 50 % level.

    >>> import numpy as np
    >>> from jaxlimb.models import EllipseParams, ellipse_intensity
    >>> p = EllipseParams(r0=100.0, c0=120.0, a=40.0, theta=0.0, rho=0.75, k=2.0, ymax=200.0, ymin=10.0)
    >>> rc = np.array([[100.0, 120.0], [100.0, 160.0], [70.0, 120.0], [60.0, 120.0]])
    >>> np.round(np.asarray(ellipse_intensity(p, rc), dtype=float), 2)
    array([200., 105., 105.,  10.])
    """
    x, y = ellipse_coords(p, rc)
    beta = _safe_norm(p.rho * x, y)
    return _levels(p, p.k * (beta - p.rho * p.a))


def ellipse_intensity_jac(p: EllipseParams, rc: Float[Array, "n 2"]) -> Float[Array, "n 8"]:
    r"""Analytic Jacobian of the ESF, Sec. V-C of [1]_; columns ``(r0, c0, a, theta, rho, k, ymax, ymin)``.

    With :math:`\beta_i = \sqrt{\rho^2 x_i^2 + y_i^2}`, :math:`\alpha_i = e^{k(\rho a - \beta_i)}`
    and :math:`g_i = (y_{\min}-y_{\max})\alpha_i/(1+\alpha_i)^2`, the paper's set is

    .. math::
        \partial f/\partial r_0 &= g k\,(\rho^2 x_i\sin\vartheta + y_i\cos\vartheta)/\beta_i \\
        \partial f/\partial c_0 &= g k\,(y_i\sin\vartheta - \rho^2 x_i\cos\vartheta)/\beta_i \\
        \partial f/\partial a &= -g k \rho \\
        \partial f/\partial\vartheta &= g k\,x_i y_i(\rho^2 - 1)/\beta_i \\
        \partial f/\partial k &= -g\,(\rho a - \beta_i), \quad
        \partial f/\partial y_{\max} = \alpha/(1+\alpha), \quad
        \partial f/\partial y_{\min} = 1/(1+\alpha)

    The paper holds :math:`\rho` fixed and prints no :math:`\partial f/\partial\rho`; ours
    (same chain rule) is :math:`\partial f/\partial\rho = -g k\,(a - \rho x_i^2/\beta_i)`.

    Parameters
    ----------
    p : EllipseParams
        The point at which to differentiate.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n, 8)
        :math:`\partial f_i/\partial(r_0, c_0, a, \vartheta, \rho, k, y_{\max}, y_{\min})`, columns in the field
        order of ``p``.
    """
    return jnp.stack(_ellipse_jac_columns(p, rc), axis=-1)


def _ellipse_jac_columns(p: EllipseParams, rc: Float[Array, "n 2"]) -> tuple[Array, ...]:
    """Columns of :func:`ellipse_intensity_jac` (stacked by the caller in the layout it needs)."""
    return _ellipse_value_and_columns(p, rc)[1]


def _ellipse_value_and_columns(p: EllipseParams, rc: Float[Array, "n 2"]) -> tuple[Array, tuple[Array, ...]]:
    """Intensity and Jacobian columns of the ESF (Sec. V-C) from one pass over the pixels."""
    x, y = ellipse_coords(p, rc)
    beta = _safe_norm(p.rho * x, y)
    z = p.k * (beta - p.rho * p.a)
    s, sc = _pair(z)
    g = (p.ymin - p.ymax) * s * sc
    inv_beta = jnp.where(beta > 0, 1.0 / jnp.where(beta > 0, beta, 1.0), 0.0)
    ct, st = jnp.cos(p.theta), jnp.sin(p.theta)
    rho2 = p.rho * p.rho
    d_r0 = g * p.k * (rho2 * x * st + y * ct) * inv_beta
    d_c0 = g * p.k * (y * st - rho2 * x * ct) * inv_beta
    d_a = -g * p.k * p.rho
    d_th = g * p.k * x * y * (rho2 - 1.0) * inv_beta
    d_rho = -g * p.k * (p.a - p.rho * x * x * inv_beta)
    d_k = -g * (p.rho * p.a - beta)
    return p.ymax * sc + p.ymin * s, (d_r0, d_c0, d_a, d_th, d_rho, d_k, sc, s)


LINEAR = LimbModel("linear", LinearParams, linear_intensity, linear_intensity_jac, _linear_jac_columns,
                   _linear_value_and_columns)
"""The linear sigmoid model (Eq. 12-14)."""
CIRCLE = LimbModel("circle", CircleParams, circle_intensity, circle_intensity_jac, _circle_jac_columns,
                   _circle_value_and_columns)
"""The circular sigmoid model (Eq. 16-17)."""
ELLIPSE = LimbModel("ellipse", EllipseParams, ellipse_intensity, ellipse_intensity_jac, _ellipse_jac_columns,
                   _ellipse_value_and_columns)
"""The elliptical sigmoid model (Sec. V-C)."""

MODELS: dict[str, LimbModel] = {m.name: m for m in (LINEAR, CIRCLE, ELLIPSE)}
