r"""The radial blur integral of the physical limb profile (:mod:`jaxlimb.models.lunar_lambert`) and its quadrature.

The blurred profile at a distance ``d`` from the centre of the body's image, limb radius ``R`` along the ray, of a
radiance ``J`` of the depth :math:`u' = R - d' = v^2` below the limb:

.. math:: F_1(d) = \int_{v_0}^{v_1} J(v)\, N(d - R + v^2; \sigma_e)\, 2v\,dv, \qquad
          F = F_1 + \frac{\sigma_e^2}{2d}\,\frac{\partial F_1}{\partial d}

(the 1-D radial blur and the first-order curvature term of the 2-D blur of a round edge, the ``(1/r) d/dr`` part
of the Laplacian).  The substitution :math:`u' = v^2` removes the square-root behaviour of the radiance at the limb.
The window :math:`v_{0,1} = \sqrt{\max(0, R - d \mp 6\sigma_e)}` (:func:`blur_window`) is cut, for the radiance,
to its lit side of the terminator (:func:`~jaxlimb.models.profile_radiance.lit_limits`), and the integral taken by
a Gauss-Legendre rule of :data:`N_NODES` nodes on it (:func:`blur_nodes`; :func:`quadrature_nodes` swaps the
rule).  :func:`blur_moments` sums a radiance over the nodes into :math:`F_1`, its ``d`` derivatives and ``F``.

The rule's derivative.  The profile's Jacobian is the derivative of the quadrature *as computed*: the integrand
differentiated at fixed nodes, plus the move of the nodes with the window's ends.  For
:math:`Q = (v_1 - v_0)\sum_i w_i h(v_i)` with :math:`v_i = v_0 (1 - x_i)/2 + v_1 (1 + x_i)/2`,

.. math:: \frac{\partial Q}{\partial v_1} = \sum_i w_i h_i + (v_1 - v_0)\sum_i w_i h'(v_i)\frac{1 + x_i}{2},
          \qquad
          \frac{\partial Q}{\partial v_0} = -\sum_i w_i h_i + (v_1 - v_0)\sum_i w_i h'(v_i)\frac{1 - x_i}{2}

(:func:`window_terms`; for the exact integral these are :math:`\pm h(v_{1,0})`, ~0 six sigma out in the
Gaussian and at the terminator, where the radiance vanishes: the integrand differentiated under the integral
alone differs from ``jax.jacfwd`` by the rule's error, ~5e-4 of a column at 20 nodes).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._programs import register_trace_setting
from .profile_radiance import WINDOW_KEYS, lit_limits

#: Gauss-Legendre nodes of the blur integral (module docstring).
N_NODES = 20
_GL_X, _GL_W = np.polynomial.legendre.leggauss(N_NODES)


@contextmanager
def quadrature_nodes(n: int) -> Iterator[None]:
    """Evaluate the profile with an ``n``-node rule inside the block (functions traced inside it): to measure the
    rule's error against the integral (the Jacobian is the derivative of whichever rule is used).

    Parameters
    ----------
    n : int
        Gauss-Legendre nodes of the blur integral (default outside the block: :data:`N_NODES`).
    """
    global _GL_X, _GL_W
    old = _GL_X, _GL_W
    _GL_X, _GL_W = np.polynomial.legendre.leggauss(int(n))
    try:
        yield
    finally:
        _GL_X, _GL_W = old


register_trace_setting("blur_quadrature.quadrature_nodes", lambda: str(len(_GL_X)))  # traced programs depend on it


def blur_window(d, R, se, lit=None, partials: bool = False):
    """The blur integral's window in ``v`` (depth ``v^2``): ``R - d -+ 6 se``, cut to its lit side of the terminator
    (:func:`~jaxlimb.models.profile_radiance.lit_limits`) for the radiance.

    Parameters
    ----------
    d, R : jax.Array (n,)
        Distance of each pixel from the centre and the limb radius along its ray (px).
    se : float or jax.Array
        Blur sigma with the pixel's box (px).
    lit : tuple or None
        ``(p, cpsi, alpha0)``: cut at the terminator; ``None`` (the glow, which the terminator does not bound): uncut.
    partials : bool
        Also the ends' partials over :data:`~jaxlimb.models.profile_radiance.WINDOW_KEYS`, ``(6, n)`` each.

    Returns
    -------
    tuple of jax.Array
        ``(v0, v1)``, with ``partials`` ``(v0, v1, dv0, dv1)``.
    """
    u0, u1 = R - d - 6.0 * se, R - d + 6.0 * se
    v0, v1 = jnp.sqrt(jnp.maximum(u0, 1e-12)), jnp.sqrt(jnp.maximum(u1, 1e-12))
    if not partials:
        return (v0, v1) if lit is None else lit_limits(lit[0], v0, v1, R, lit[1], lit[2])
    shape = (len(WINDOW_KEYS),) + (1,) * jnp.ndim(u0)  # partials over WINDOW_KEYS, stacked: (6, n)
    dv0 = jnp.where(u0 > 1e-12, 0.5 / v0, 0.0) * jnp.array([-1.0, 1.0, -6.0, 0.0, 0.0, 0.0]).reshape(shape)
    dv1 = jnp.where(u1 > 1e-12, 0.5 / v1, 0.0) * jnp.array([-1.0, 1.0, 6.0, 0.0, 0.0, 0.0]).reshape(shape)
    if lit is None:
        return v0, v1, dv0, dv1
    return lit_limits(lit[0], v0, v1, R, lit[1], lit[2], dv0, dv1)


def blur_nodes(d, R, se, v0, v1):
    """The Gauss-Legendre quadrature of the radial blur (module docstring) on ``[v0, v1]``.

    Parameters
    ----------
    d, R : jax.Array (n,)
        As :func:`blur_window`.
    se : float or jax.Array
        Blur sigma (px).
    v0, v1 : jax.Array (n,)
        The window (:func:`blur_window`).

    Returns
    -------
    tuple of jax.Array (n, nodes)
        The nodes ``v``, the Gaussian's argument ``t = (d - R + v^2) / se``, its density and the weights ``g`` (the
        density x ``2v dv`` x the rule's weights): ``sum(h(v) g)`` blurs a radiance ``h`` of the depth ``v^2``.
    """
    half = 0.5 * (v1 - v0)
    v = half[..., None] * (jnp.asarray(_GL_X) + 1.0) + v0[..., None]  # (n, nodes)
    sn = jnp.asarray(se)[..., None]  # one sigma_e per pixel (AnisoProfileParams) or one for all
    t = (d[..., None] - R[..., None] + v * v) / sn  # (d - d') / se
    gauss = jnp.exp(-0.5 * t * t) / (sn * math.sqrt(2 * math.pi))
    return v, t, gauss, gauss * v * (jnp.asarray(_GL_W) * (2.0 * half)[..., None])


class BlurMoments(NamedTuple):
    """The blur of a radiance on the nodes of :func:`blur_nodes` (:func:`blur_moments`), per pixel."""

    F: jax.Array
    """The profile ``F1 + se^2/(2d) dF1/dd`` (module docstring)."""
    F1: jax.Array
    """The 1-D radial blur."""
    F1_d: jax.Array
    """``dF1/dd``."""
    F1_dd: jax.Array | None
    """``d^2F1/dd^2`` (``None`` unless asked for)."""
    F1_dse: jax.Array | None
    """``-int J t (t^2 - 3) g / se^2``: the ``se`` partial of ``dF1/dd`` up to the chain factor (``None`` unless
    asked for)."""


def curvature_blur(F1, F1_d, se, d):
    """The profile ``F1 + se^2/(2d) dF1/dd`` (module docstring) of a radial blur ``F1`` and its derivative in ``d``.

    Parameters
    ----------
    F1, F1_d : jax.Array
        The 1-D blur and its ``d`` derivative.
    se : float or jax.Array
        Blur sigma (px), broadcast with ``d``.
    d : jax.Array
        Distance from the centre of the body's image (px).

    Returns
    -------
    jax.Array
        The blur with the first-order curvature term of the 2-D blur of a round edge.
    """
    return F1 + se * se / (2.0 * d) * F1_d


def blur_moments(J, t, g, se, d, second: bool = False, basis=None) -> BlurMoments:
    """The blur of a radiance ``J`` on the nodes of :func:`blur_nodes` (module docstring): ``F1 = int J g``,
    ``dF1/dd = -int J t g / se`` and the profile ``F`` (:func:`curvature_blur`), summed over the nodes.

    Parameters
    ----------
    J : jax.Array (n, nodes)
        The radiance at the nodes.
    t, g : jax.Array (n, nodes)
        The Gaussian's argument and the weights of :func:`blur_nodes`.
    se : float or jax.Array (n,)
        Blur sigma (px).
    d : jax.Array (n,)
        Distance from the centre of the body's image (px).
    second : bool
        Also ``d^2F1/dd^2`` and the ``se`` partial of ``dF1/dd`` (:class:`BlurMoments`).
    basis : jax.Array (n, nodes, m), optional
        Functions of the node to weigh ``J`` by: the moments of ``J`` times each, with a trailing axis ``m``.

    Returns
    -------
    BlurMoments
        ``(F, F1, F1_d, F1_dd, F1_dse)``, each ``(n,)`` (``(n, m)`` with ``basis``); the last two ``None`` unless
        ``second``.
    """
    def total(x):  # the sum over the nodes
        return jnp.sum(x, axis=-1) if basis is None else jnp.einsum("nq,nqm->nm", x, basis)

    sn = jnp.asarray(se)[..., None]  # one sigma for every pixel or one per pixel, on the nodes' axis
    s, dd = (se, d) if basis is None else (sn, d[..., None])  # with a basis, the moments' trailing axis
    F1, F1_d = total(J * g), -total(J * t * g / sn)
    F = curvature_blur(F1, F1_d, s, dd)
    if not second:
        return BlurMoments(F, F1, F1_d, None, None)
    return BlurMoments(F, F1, F1_d, total(J * (t * t - 1.0) * g) / (s * s), -total(J * t * (t * t - 3.0) * g) / (s * s))


def window_terms(J, J_v, S, nodes, se, s2d, v0, v1):
    """``d(F1 + s2d dF1/dd)/dv0`` and ``/dv1`` of the blur of ``J`` on ``nodes``: the quadrature's change with its
    ends (module docstring).  With ``N`` the Gaussian density, ``F1 = (v1 - v0) sum_i w_i h_i`` for ``h = J v N``,
    and ``dF1/dd`` the same sum of ``-h t / se``; ``d(v N)/dv = v N (1/v - 2 v t / se)``, so every sum is one of the
    blur's weights ``g`` times a factor.

    Parameters
    ----------
    J, J_v : jax.Array (n, nodes)
        The radiance at the nodes and its derivative in ``v``.
    S : jax.Array (n,)
        Its blur ``F1 + s2d dF1/dd`` (:func:`blur_moments`).
    nodes : tuple of jax.Array (n, nodes)
        :func:`blur_nodes`.
    se : float or jax.Array (n,)
        Blur sigma (px).
    s2d : jax.Array (n,)
        ``se^2 / (2 d)``.
    v0, v1 : jax.Array (n,)
        The window (:func:`blur_window`).

    Returns
    -------
    tuple of jax.Array (n,)
        The derivatives of ``S`` in ``v0`` and in ``v1``.
    """
    v, t, g = nodes[0], nodes[1], nodes[3]
    sn, s = jnp.asarray(se)[..., None], s2d[..., None]
    P = J_v + J * (1.0 / v - 2.0 * v * t / sn)  # h_v / (v N)
    Q = P - s * (P * t + J * 2.0 * v / sn) / sn  # the v-derivative of the integrand of F1 + s2d dF1/dd, / (v N)
    Qg = jax.lax.optimization_barrier(Q * g)  # once, for both sums (each would repeat the radiance's chain)
    A, B = jnp.sum(Qg, axis=-1), jnp.sum(Qg * jnp.asarray(_GL_X), axis=-1)
    width = v1 - v0
    S_w = S * jnp.where(width > 0, 1.0 / jnp.where(width > 0, width, 1.0), 0.0)  # (at width 0: dv0 = dv1, no term)
    return -S_w + 0.5 * (A - B), S_w + 0.5 * (A + B)


__all__ = ["N_NODES", "BlurMoments", "blur_moments", "blur_nodes", "blur_window", "curvature_blur",
           "quadrature_nodes", "window_terms"]
