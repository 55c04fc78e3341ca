r"""The pieces of the physical limb profile (:mod:`jaxlimb.models.lunar_lambert`) evaluated at one depth: the
lunar-Lambert radiance and its partial derivatives, the terminator's depth along a ray and the window of the blur
integral cut to its lit side (both with their partial derivatives) and the anisotropic blur's angular terms; and per
pixel, its geometry relative to the limb ellipse and the branch its window takes (the glow above the limb:
:mod:`jaxlimb.models.profile_glow`).

The derivatives are those of the functions as written (the quadrature of :mod:`jaxlimb.models.blur_quadrature`
moves its nodes with the window's ends, so its exact Jacobian needs the radiance's derivative in the depth and the
ends' derivatives in every per-pixel quantity: :func:`radiance_parts`' ``I_v``, :func:`lit_limits`' partials).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .profile_params import AnisoProfileParams, LimbProfileParams
from .sigmoid import ellipse_coords

#: The per-pixel quantities the window's ends depend on: distance ``d``, limb radius ``R``, blur ``se``, the
#: cosine ``cpsi`` toward the Sun, the angular radius ``a0`` and the phase ``ph``.
WINDOW_KEYS = ("d", "R", "se", "cpsi", "a0", "ph")

def cos_sin_small(x, small):
    """``(cos x, sin x)``; by Taylor series (to 1e-16 for ``|x| <= 0.2``) when ``small`` (a
    scalar: the body's angular radius, which bounds ``|x|``, is below 0.2 rad), else
    ``jnp.cos``, ``jnp.sin`` (the series is ~5x cheaper).

    Parameters
    ----------
    x : jax.Array
        Angles (rad).
    small : bool or jax.Array ()
        Whether every ``|x|`` is at most 0.2 rad (a traced scalar is allowed: the branch is a ``lax.cond``).

    Returns
    -------
    cos, sin : jax.Array
        Cosine and sine of ``x``, shape of ``x``.
    """

    def series(x):
        x2 = x * x
        c = 1.0 - x2 / 2.0 * (1.0 - x2 / 12.0 * (1.0 - x2 / 30.0 * (1.0 - x2 / 56.0 * (1.0 - x2 / 90.0))))
        s = x * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0 * (1.0 - x2 / 110.0)))))
        return c, s

    return jax.lax.cond(small, series, lambda x: (jnp.cos(x), jnp.sin(x)), x)


def radiance_parts(p: LimbProfileParams, v, R, cpsi, alpha0, brightened: bool = True):
    """Radiance and its partial derivatives at depth ``v**2`` below the limb (module docstring of
    :mod:`jaxlimb.models.lunar_lambert`).

    With ``q = 1 - v^2/R`` the emission cosine is computed as ``mu = v sqrt((1 + q)/R)``
    (no cancellation in ``1 - q^2`` at the limb).  The weight is ``L + L_slope min(L, L_ref) dg`` at the point,
    ``dg`` the phase angle's change across the disc: ``cos(phase + dg) = cos beta cos(phase) - sin beta sin(phase)
    cpsi``.  Returns ``I`` and, at fixed ``v``, ``dI/dR``, ``dI/dcpsi``, ``dI/dalpha0``, ``dI/dphase``, ``dI/dL``,
    ``dI/dkappa``, ``dI/dv`` at fixed ``R`` (the move of a quadrature node), ``dI/dL_slope`` and ``dI/dL_ref``.
    ``brightened``:
    with the limb brightening ``(mu0 mu)^-p.kappa`` (:class:`MinnaertProfileParams`); ``dI/dkappa`` is returned in
    either case (at ``kappa = 0`` without it).  A separate model and not a parameter held at 0: on CPU the
    brightening's terms cost the one-pass Jacobian 2.5-3x (XLA repeats them in every column's reduction; a
    ``lax.cond`` on ``kappa = 0`` did not help).

    Parameters
    ----------
    p : LimbProfileParams
        Supplies ``phase`` (rad), ``L``, ``L_slope``, ``L_ref`` and, with ``brightened``, ``kappa``.
    v : jax.Array
        Square root of the depth below the limb (px^1/2): the quadrature nodes, ``(n, nodes)``.
    R : jax.Array
        Limb radius along each pixel's ray (px), broadcastable against ``v``.
    cpsi : jax.Array
        Cosine of the angle between the pixel's direction and the Sun's image direction, broadcastable against ``v``.
    alpha0 : jax.Array ()
        Angular radius of the body (rad).
    brightened : bool
        Multiply by the limb brightening ``(mu0 mu)^-kappa`` (:class:`MinnaertProfileParams`).

    Returns
    -------
    tuple of 10 jax.Array
        ``(I, I_R, I_cpsi, I_a0, I_ph, I_L, I_k, I_v, I_s, I_ref)``, each of the broadcast shape of ``v``: the
        radiance (units of ``amp``) and its partials in ``R``, ``cpsi``, ``alpha0``, ``phase``, ``L``, ``kappa`` (all
        at fixed ``v``), in ``v`` (at fixed ``R``), in ``L_slope`` and in ``L_ref``.
    """
    r = _ray(p, v, R, cpsi, alpha0)
    G, dg, below, scale, Lp = _point_weight(p, r, cpsi)
    I, I_mu0, I_mu, I_L, log_mm, kappa = _lunar_lambert(p, r, Lp, brightened)
    mu0_beta, q_R, q_v, I_R, I_v = _depth_partials(r, v, R, alpha0, I, I_mu0, I_mu, kappa, brightened)
    I_cpsi = I_mu0 * r.s_em * r.sph
    I_a0 = I_mu0 * mu0_beta * r.q
    I_ph = I_mu0 * (r.s_em * r.cph * cpsi - r.c_em * r.sph)
    # the weight's own change with the point, through dg (beta = q alpha0; q_R = v^2 / R^2 at fixed v, q_v = -2 v / R
    # at fixed R)
    Ls = scale * p.L_slope * I_L
    k = Ls * G * (-r.sb * r.cph - r.cb * r.a_s)  # d dg / d beta
    turn = p.L_slope * dg * I_L
    return (I, I_R + k * alpha0 * q_R, I_cpsi - Ls * G * r.sb * r.sph, I_a0 + k * r.q,
            I_ph + Ls * (G * (-r.cb * r.sph - r.sb * r.cph * cpsi) - 1.0), I_L + jnp.where(below, turn, 0.0),
            -log_mm * I, I_v + k * alpha0 * q_v, scale * dg * I_L, jnp.where(below, 0.0, turn))


class _Ray(NamedTuple):
    """A ray at depth ``v**2`` below the limb (:func:`radiance_parts`): ``q = 1 - v^2/R``, ``rt = sqrt((1 + q)/R)``,
    the emission cosine ``mu``, the turn ``beta = q alpha0`` as ``cb, sb``, ``s_em, c_em = sin, cos(e - beta)``, the
    phase's ``sph, cph``, ``a_s = sph cpsi``, where the incidence cosine ``mu0`` is positive (``lit``), ``m0``
    (``mu0`` there, 0 elsewhere) and ``inv_den = 1 / (m0 + mu)``."""

    v2: jax.Array
    inv_R: jax.Array
    q: jax.Array
    rt: jax.Array
    mu: jax.Array
    cb: jax.Array
    sb: jax.Array
    s_em: jax.Array
    c_em: jax.Array
    sph: jax.Array
    cph: jax.Array
    a_s: jax.Array
    lit: jax.Array
    m0: jax.Array
    inv_den: jax.Array


def _ray(p: LimbProfileParams, v, R, cpsi, alpha0) -> _Ray:
    """The :class:`_Ray` at depth ``v**2`` (emission and incidence cosines, the ray's turn)."""
    v2 = v * v
    inv_R = 1.0 / R
    q = jnp.clip(1.0 - v2 * inv_R, 0.0, 1.0)
    rt = jnp.sqrt((1.0 + q) * inv_R)
    mu = v * rt
    cb, sb = cos_sin_small(q * alpha0, jnp.abs(alpha0) <= 0.2)  # beta = q alpha0
    s_em = q * cb - mu * sb  # sin(e - beta)
    c_em = mu * cb + q * sb  # cos(e - beta)
    sph, cph = jnp.sin(p.phase), jnp.cos(p.phase)
    a_s = sph * cpsi
    mu0 = s_em * a_s + c_em * cph
    lit = mu0 > 0
    m0 = jnp.where(lit, mu0, 0.0)
    inv_den = 1.0 / jnp.where(lit, m0 + mu, 1.0)
    return _Ray(v2, inv_R, q, rt, mu, cb, sb, s_em, c_em, sph, cph, a_s, lit, m0, inv_den)


def _point_weight(p: LimbProfileParams, r: _Ray, cpsi):
    """``G = d acos(cg) / d cg``, the phase angle's change ``dg`` across the disc, the weight's branch
    (``L < L_ref``), its ``scale = min(L, L_ref)`` and the weight ``Lp`` at the point."""
    # the phase angle at the point: the ray is turned by beta from the centre's, toward the Sun by cpsi
    cg = jnp.clip(r.cb * r.cph - r.sb * r.sph * cpsi, -1.0, 1.0 - 1e-15)
    G = -1.0 / jnp.sqrt(1.0 - cg * cg)  # d acos(cg) / d cg
    dg = jnp.arccos(cg) - p.phase
    below = p.L < p.L_ref
    scale = jnp.where(below, p.L, p.L_ref)  # min(L, L_ref): relative below McEwen's weight, absolute above
    Lp = p.L + p.L_slope * scale * dg  # the weight at the point
    return G, dg, below, scale, Lp


def _lunar_lambert(p: LimbProfileParams, r: _Ray, Lp, brightened: bool):
    """The radiance ``I``, its partials in ``mu0``, ``mu`` and the weight ``L``, ``log(mu0 mu)`` and the
    brightening's exponent ``kappa`` (0 without it)."""
    mu, m0, inv_den = r.mu, r.m0, r.inv_den
    two_L = 2.0 * Lp
    ratio = m0 * inv_den  # mu0 / (mu0 + mu)
    # (mu0 mu)^-kappa: Minnaert's limb brightening (L = 0: mu0^k mu^(k-1) with k = 1 - kappa); 1 at kappa = 0
    log_mm = jnp.log(jnp.where(r.lit & (mu > 0), m0 * mu, 1.0))
    kappa = p.kappa if brightened else 0.0
    brighten = jnp.exp(-kappa * log_mm) if brightened else 1.0
    I = (two_L * ratio + (1.0 - Lp) * m0) * brighten
    # d/dmu0 of the brightened law: its lunar-Lambert part minus kappa I / mu0 (ratio / mu0 = inv_den)
    I_mu0 = jnp.where(r.lit, (two_L * (mu * inv_den - kappa) * inv_den + (1.0 - Lp) * (1.0 - kappa)) * brighten, 0.0)
    I_mu = -two_L * ratio * inv_den * brighten
    I_L = (2.0 * ratio - m0) * brighten
    return I, I_mu0, I_mu, I_L, log_mm, kappa


def _depth_partials(r: _Ray, v, R, alpha0, I, I_mu0, I_mu, kappa, brightened: bool):
    """``d mu0 / d beta``, ``q_R`` (fixed ``v``), ``q_v`` (fixed ``R``) and the radiance's partials ``I_R`` at
    fixed ``v`` and ``I_v`` at fixed ``R``, without the weight's change with the point."""
    v2, inv_R, q, rt, cb, sb, a_s, cph = r.v2, r.inv_R, r.q, r.rt, r.cb, r.sb, r.a_s, r.cph
    mu0_beta = -r.c_em * a_s + r.s_em * cph  # d mu0 / d beta
    q_R = v2 * inv_R * inv_R
    mu_R = -v * q * inv_R / (R * rt)
    s_R = q_R * cb - mu_R * sb
    c_R = mu_R * cb + q_R * sb
    mu0_R = s_R * a_s + c_R * cph + mu0_beta * q_R * alpha0
    # the mu part of d(mu^-kappa)/dR at fixed v: -kappa I (mu_R / mu), mu_R / mu = -q / (R (1 + q)) (finite at the limb)
    I_R = I_mu0 * mu0_R + I_mu * mu_R
    if brightened:
        I_R = I_R + kappa * I * q / (R * (1.0 + q))
    # at fixed R along v: q_v = -2 v / R, mu_v = 2 q / (R rt) (d rt / dv = q_v / (2 R rt)), beta_v = q_v alpha0
    q_v = -2.0 * v * inv_R
    mu_v = 2.0 * q * inv_R / rt
    mu0_v = (q_v * cb - mu_v * sb) * a_s + (mu_v * cb + q_v * sb) * cph + mu0_beta * q_v * alpha0
    I_v = I_mu0 * mu0_v + I_mu * mu_v
    if brightened:  # the mu part of d(mu^-kappa)/dv: -kappa I mu_v / mu, mu_v / mu = 2 q / (v (1 + q))
        I_v = I_v - kappa * I * 2.0 * q / (v * (1.0 + q))
    return mu0_beta, q_R, q_v, I_R, I_v


def terminator_depth(p: LimbProfileParams, R, cpsi, alpha0, tangents: bool = False):
    """``v_t``, the root of the depth where the ray meets the terminator (``mu0 = 0``), and which side is lit.

    ``mu0 = sin(g) sin(phase) cpsi + cos(g) cos(phase)`` with ``g = e - beta = e - alpha0 sin e`` (module
    docstring) vanishes at ``g_t = atan(-cos(phase) / (sin(phase) cpsi))`` in ``(-pi/2, pi/2]``; ``e_t`` from
    two Newton steps on ``e - alpha0 sin e = g_t`` from ``g_t + alpha0 sin g_t`` (one left ``v_t`` off by
    O(alpha0^4) rad, and the columns 3e-4 from autodiff at a 0.21 rad body's horn), then ``v_t^2 = R (1 - sin e_t)``.
    Also returns whether the shallow side (``g > g_t``) is the lit one: ``d mu0 / dg`` at the unwrapped root
    ``atan2(-cos(phase), sin(phase) cpsi)`` is ``sqrt(a_s^2 + cos^2 phase) > 0``, and it changes sign when the
    root is shifted by pi into ``(-pi/2, pi/2]``.  A root beyond the centre (``g_t < 0``) gives ``v_t`` at the
    centre, one beyond the limb ``v_t = 0``: the caller's clip to the window then keeps all or none of it.
    With ``tangents``, also ``d v_t`` over :data:`WINDOW_KEYS`, ``(6, n)`` (the Newton steps differentiated).

    Parameters
    ----------
    p : LimbProfileParams
        Supplies the phase angle ``phase`` (rad).
    R : jax.Array (n,)
        Limb radius along each pixel's ray (px).
    cpsi : jax.Array (n,)
        Cosine of the angle between each pixel's direction and the Sun's image direction.
    alpha0 : jax.Array ()
        Angular radius of the body (rad).
    tangents : bool
        Also return the partials of ``v_t``.

    Returns
    -------
    vt : jax.Array (n,)
        Square root of the terminator's depth below the limb (px^1/2).
    shallow_lit : jax.Array (n,) of bool
        Whether the shallow side of the terminator (``v < v_t``, toward the limb) is the lit one.
    dvt : jax.Array (6, n)
        Only with ``tangents``: the partials of ``vt`` over :data:`WINDOW_KEYS`.
    """
    sph, cph = jnp.sin(p.phase), jnp.cos(p.phase)
    theta = jnp.arctan2(-cph, sph * cpsi)
    wrapped = (theta > 0.5 * math.pi) | (theta <= -0.5 * math.pi)
    g = jnp.where(theta > 0.5 * math.pi, theta - math.pi, jnp.where(theta <= -0.5 * math.pi, theta + math.pi, theta))
    e = g + alpha0 * jnp.sin(g)
    # tangents along (cpsi, a0, ph): d theta (the shift by pi is a constant) and d alpha0
    den = (sph * cpsi) ** 2 + cph * cph
    dg = jnp.stack([sph * cph / den, jnp.zeros_like(den), cpsi / den])
    da = jnp.array([0.0, 1.0, 0.0]).reshape((3,) + (1,) * jnp.ndim(e))
    de = dg * (1.0 + alpha0 * jnp.cos(g)) + da * jnp.sin(g)
    e, de = _newton_steps(e, de, g, dg, da, alpha0, tangents)
    if tangents:  # materialised: the partials' rows below would each repeat the Newton steps (XLA's loop fusion)
        e, de = jax.lax.optimization_barrier((e, de))
    ec = jnp.clip(e, 0.0, 0.5 * math.pi)
    depth2 = R * (1.0 - jnp.sin(ec))
    vt = jnp.sqrt(jnp.maximum(depth2, 1e-12))
    if not tangents:
        return vt, ~wrapped  # (as v0, v1)
    half_inv = jnp.where(depth2 > 1e-12, 0.5 / vt, 0.0)
    d_e = half_inv * (-R * jnp.cos(ec)) * jnp.where((e > 0.0) & (e < 0.5 * math.pi), de, 0.0)  # (cpsi, a0, ph)
    zero = jnp.zeros_like(vt)
    return vt, ~wrapped, jnp.stack([zero, half_inv * (1.0 - jnp.sin(ec)), zero, d_e[0], d_e[1], d_e[2]])


def _newton_steps(e, de, g, dg, da, alpha0, tangents: bool):
    """Two Newton steps on ``e - alpha0 sin e = g`` from ``e``; with ``tangents`` also those of the tangents ``de``
    (``(3, n)`` along ``(cpsi, a0, ph)``, given ``dg`` and ``da``)."""
    for _ in range(2):  # error O(alpha0^8) rad: the cut must sit on the terminator
        sin_e, cos_e = jnp.sin(e), jnp.cos(e)
        f, fp = e - alpha0 * sin_e - g, 1.0 - alpha0 * cos_e
        if tangents:
            df = fp * de - da * sin_e - dg
            de = de - (df * fp - f * (alpha0 * sin_e * de - da * cos_e)) / (fp * fp)
        e = e - f / fp
    return e, de


def lit_limits(p: LimbProfileParams, v0, v1, R, cpsi, alpha0, dv0=None, dv1=None):
    """The blur integral's limits cut to the lit part of ``[v0, v1]``; with the limits' partials ``dv0, dv1``
    (``(6, n)`` over :data:`WINDOW_KEYS`) also the cut limits' partials.

    The radiance is 0 beyond the terminator and its slope jumps there; a Gauss-Legendre rule across that
    kink converges slowly (at a 117 deg crescent's horn, 20 nodes put the intensity 0.17 DN of 217 off and
    the columns of the rule several % off at 64 nodes), while on the lit segment alone the integrand is smooth.
    A ray meets the terminator at most once (``mu0`` is a sinusoid in ``e - beta``, which spans less than pi).

    Parameters
    ----------
    p : LimbProfileParams
        Supplies the phase angle ``phase`` (rad).
    v0, v1 : jax.Array (n,)
        The window's ends in ``v`` (square root of the depth, px^1/2).
    R : jax.Array (n,)
        Limb radius along each pixel's ray (px).
    cpsi : jax.Array (n,)
        Cosine of the angle between each pixel's direction and the Sun's image direction.
    alpha0 : jax.Array ()
        Angular radius of the body (rad).
    dv0, dv1 : jax.Array (6, n), optional
        Partials of ``v0``, ``v1`` over :data:`WINDOW_KEYS`; ``None``: no partials.

    Returns
    -------
    tuple of jax.Array
        ``(v0, v1)`` cut to the lit segment (equal where none of the window is lit), and with ``dv0, dv1`` given
        also their partials ``(6, n)`` each.
    """
    # g = e - beta falls monotonically with depth (dg/de = 1 - alpha0 cos e > 0): the shallow side of v_t is
    # [v0, v_t], the deep side [v_t, v1]
    if dv0 is None:
        vt, shallow_lit = terminator_depth(p, R, cpsi, alpha0)
        vt = jnp.clip(vt, v0, v1)
        return jnp.where(shallow_lit, v0, vt), jnp.where(shallow_lit, vt, v1)
    # materialised: XLA would otherwise repeat the Newton steps in the fusion of every partial that reads them
    vt, shallow_lit, dvt = jax.lax.optimization_barrier(terminator_depth(p, R, cpsi, alpha0, tangents=True))
    dvt = jnp.where(vt < v0, dv0, jnp.where(vt > v1, dv1, dvt))
    vt = jnp.clip(vt, v0, v1)
    return (jnp.where(shallow_lit, v0, vt), jnp.where(shallow_lit, vt, v1), jnp.where(shallow_lit, dv0, dvt),
            jnp.where(shallow_lit, dvt, dv1))


def limb_geometry(p: LimbProfileParams, rc):
    """``(dr, dc, x, y, d, beta, R, cpsi)`` of the pixels ``rc``: offsets from the centre, ellipse-frame
    coordinates, distance ``d`` from the centre, the limb's radius ``R`` in the pixel's direction and the
    cosine of its angle from the Sun's image direction (module docstring of :mod:`jaxlimb.models.lunar_lambert`).

    Parameters
    ----------
    p : LimbProfileParams
        Supplies the ellipse ``(r0, c0, a, theta, rho)`` and the Sun's unit image direction ``(sun_r, sun_c)``.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    tuple of 8 jax.Array (n,)
        ``(dr, dc, x, y, d, beta, R, cpsi)``; lengths in px.
    """
    rc = jnp.asarray(rc)
    dr = rc[..., 0] - p.r0
    dc = rc[..., 1] - p.c0
    x, y = ellipse_coords(p, rc)
    d2 = dr * dr + dc * dc
    d = jnp.sqrt(jnp.where(d2 > 0, d2, 1.0))
    b2 = p.rho * p.rho * x * x + y * y
    beta = jnp.sqrt(jnp.where(b2 > 0, b2, 1.0))
    R = p.rho * p.a * d / beta
    cpsi = (dr * p.sun_r + dc * p.sun_c) / d
    return dr, dc, x, y, d, beta, R, cpsi


def window_regime(p: LimbProfileParams, rc):
    """Which branch each pixel's window takes (an integer code): whether either end of ``R - d -+ 6 se`` is clamped at
    the limb (``v = 0``), whether the terminator is clipped to the window and which side is lit.  The quadrature is
    smooth in the parameters while these stay the same; where one switches, the rule (not the integral) has a kink of
    the size of its error -- a window end reaching the limb moves its nodes as a square root -- and central
    differences straddling it measure the kink, not the derivative (:mod:`jaxlimb.models.gradcheck`).  The sixth
    flag is the weight's branch, ``L < L_ref`` (a kink of the model itself).

    Parameters
    ----------
    p : LimbProfileParams
        The profile's parameters (any of its variants).
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,) of int32
        Six bit flags per pixel; two pixels share a branch when their codes are equal.
    """
    dr, dc, _, _, d, _, R, cpsi = limb_geometry(p, rc)
    se = jnp.sqrt(p.sigma * p.sigma + 1.0 / 12.0 + (0.0 if not isinstance(p, AnisoProfileParams)
                                                   else aniso_var(p, aniso_terms_of(p, dr, dc, d))))
    u0, u1 = R - d - 6.0 * se, R - d + 6.0 * se
    v0, v1 = jnp.sqrt(jnp.maximum(u0, 1e-12)), jnp.sqrt(jnp.maximum(u1, 1e-12))
    vt, shallow = terminator_depth(p, R, cpsi, jnp.arctan(p.rho * p.a * p.inv_f))
    below = jnp.broadcast_to(p.L < p.L_ref, jnp.shape(d))  # the weight's branch (:func:`radiance_parts`)
    flags = (u0 > 1e-12, u1 > 1e-12, vt < v0, vt > v1, shallow, below)
    return sum(f.astype(jnp.int32) << i for i, f in enumerate(flags))


def aniso_terms(dr, dc, d):
    """``cos 2psi, sin 2psi`` of the ray ``(dr, dc)`` (length ``d``; ``psi`` from ``+col`` toward ``-row``) and their
    partials in ``r0, c0`` (``dr = r - r0``).

    Parameters
    ----------
    dr, dc : jax.Array (n,)
        Pixel offsets from the centre, ``r - r0`` and ``c - c0`` (px).
    d : jax.Array (n,)
        Their length (px, > 0).

    Returns
    -------
    tuple of 6 jax.Array (n,)
        ``(C, S, C_r0, C_c0, S_r0, S_c0)``: ``cos 2psi``, ``sin 2psi`` and their partials in ``r0`` and ``c0``.
    """
    d4 = d * d * d * d
    dif = dc * dc - dr * dr
    return (dif / (d * d), -2.0 * dr * dc / (d * d), 4.0 * dr * dc * dc / d4, -4.0 * dc * dr * dr / d4,
            2.0 * dc * dif / d4, -2.0 * dr * dif / d4)


def aniso_var(p: LimbProfileParams, terms):
    r"""The anisotropic part of the blur variance of :class:`AnisoProfileParams` per pixel from its
    :func:`aniso_terms` (``None`` for the other profiles, ``terms`` then ``None``).

    Parameters
    ----------
    p : LimbProfileParams
        Supplies ``s2c``, ``s2s`` (px^2) when ``terms`` is not ``None``.
    terms : tuple of jax.Array, or None
        The output of :func:`aniso_terms_of`.

    Returns
    -------
    jax.Array (n,) or None
        ``s2c cos 2psi + s2s sin 2psi`` (px^2), added to :math:`\sigma_e^2`; ``None`` when ``terms`` is.
    """
    if terms is None:
        return None
    return p.s2c * terms[0] + p.s2s * terms[1]


def aniso_terms_of(p: LimbProfileParams, dr, dc, d):
    """:func:`aniso_terms` for :class:`AnisoProfileParams`, ``None`` for the other profiles.

    Parameters
    ----------
    p : LimbProfileParams
        The profile's parameters; only their type matters.
    dr, dc : jax.Array (n,)
        Pixel offsets from the centre, ``r - r0`` and ``c - c0`` (px).
    d : jax.Array (n,)
        Their length (px, > 0).

    Returns
    -------
    tuple of 6 jax.Array (n,), or None
        As :func:`aniso_terms`, or ``None`` when ``p`` is not :class:`AnisoProfileParams`.
    """
    return aniso_terms(dr, dc, d) if isinstance(p, AnisoProfileParams) else None
