r"""A physically based limb profile: the blurred radiance of a sunlit sphere near its limb.

Why.  A sigmoid puts its 50 % level where a *flat-topped* blurred step has it.  A real lit
limb is not flat-topped: seen from a finite range, the limb is at emission :math:`e = 90^\circ`
while the incidence there is :math:`< 90^\circ` (the view rays converge, the Sun's are
parallel), so the Lommel-Seeliger term :math:`2\mu_0/(\mu_0 + \mu)` of the lunar-Lambert law
reaches 2 in a rim a fraction of a pixel wide; and at larger phases the Lambert term dims
the limb toward the horns.  Blurred, the rim moves the sigmoid's 50 % point outward by a phase-dependent
fraction of a pixel (``benchmarks/locate_accuracy.py``).  This model fits the profile itself.

Geometry (circle model, small angles).  A pixel at distance ``d`` from the centre of the
body's image, polar direction at angle :math:`\psi'` from the Sun's image direction.  With
:math:`q = d/R` (``R`` the apparent radius, px) and :math:`\alpha_0 = \arctan(R/f)` the
angular radius, the ray is at :math:`\beta = q\,\alpha_0` from the centre direction and hits
the sphere with :math:`\sin e = \sin\beta / \sin\alpha_0 \approx q`.  In the frame with ``z``
from the body toward the observer and ``x`` along the pixel's image direction, the normal
is :math:`n = (\sin(e - \beta), \cdot, \cos(e - \beta))` (the normal is turned by ``e`` from
the direction back to the observer, which is itself turned by :math:`-\beta` from ``z``),
and the Sun direction is :math:`s = (\sin\vartheta\cos\psi', \cdot, \cos\vartheta)`
(:math:`\vartheta` the phase angle), so

.. math:: \mu_0 = \cos i = \sin(e-\beta)\sin\vartheta\cos\psi' + \cos(e-\beta)\cos\vartheta,
          \qquad \mu = \cos e = \sqrt{1 - q^2}.

Radiance (lunar-Lambert, McEwen): :math:`I = L\,2\mu_0/(\mu_0+\mu) + (1-L)\,\mu_0` for
:math:`\mu_0 > 0`, 0 otherwise, with the weight ``L`` at the point's own phase angle.

The phase angle across the disc.  Each point is seen at its own phase angle: the ray at :math:`\beta` from the
centre direction, toward the Sun by :math:`\cos\psi'`, meets the surface at the phase angle :math:`\vartheta + \Delta g`
with :math:`\cos(\vartheta + \Delta g) = \cos\beta\cos\vartheta - \sin\beta\sin\vartheta\cos\psi'` (to first order
:math:`\Delta g = \beta\cos\psi'`; at zero phase :math:`\Delta g = \beta`).  Incidence and emission are computed at
each point; the law's own phase dependence is its weight, :math:`L + \lambda\,\min(L, L_M)\,\Delta g` with ``L`` at the
centre's phase (fitted), :math:`L_M` McEwen's weight there (``L_ref``) and :math:`\lambda = d\ln L_M/d\vartheta`
(``L_slope``: :func:`~jaxlimb.models.profile_params.lunar_lambert_slope`): the fitted weight changes across the disc
as the Moon's does, relatively (a Lambert surface's, ``L = 0``, does not change), but never by more than McEwen's own
weight does, :math:`L_M' \Delta g`: near McEwen's zero (about 104 deg) :math:`\lambda` diverges, and a surface that
does not follow his law there keeps a weight far above :math:`L_M`.  Held at the centre's, the weight makes the rim toward the
Sun brighter than a lunar-Lambert surface's, the fit reads the difference as an edge moved, and the centre comes out
displaced away from the Sun by an amount first order in :math:`\alpha_0` (``benchmarks/phase_across_disc.py``).

Blur.  The observed intensity is ``ymin + amp * (I H) * N_sigma`` along the radial
direction (1-D: ``R >> sigma``): with the depth :math:`u' = R - d' = v^2`,

.. math:: f(d) = y_{\min} + A \int_{v_0}^{v_1} I(R - v^2)\, N(d - R + v^2; \sigma_e)\, 2v\,dv

by 20-point Gauss-Legendre quadrature (:mod:`~jaxlimb.models.blur_quadrature`),
:math:`v_{0,1} = \sqrt{\max(0, R - d \mp 6\sigma_e)}`
(the substitution removes the square-root behaviour of :math:`\mu` at the limb; the window is cut to
its lit side of the terminator, :func:`~jaxlimb.models.profile_radiance.lit_limits`), and
:math:`\sigma_e^2 = \sigma^2 + 1/12` (pixel integration as a box), plus the first-order
curvature term of the 2-D blur, :math:`\sigma_e^2/(2d)\,\partial f/\partial d` (without it small discs come out
short: ``benchmarks/locate_accuracy.py``'s bias study).  Parameters
``(r0, c0, a, sigma, amp, ymin)`` are estimated; ``theta, rho`` (limb ellipse shape),
``sun_r, sun_c`` (unit image direction of the Sun), ``phase`` (rad), ``inv_f`` (1/focal px;
0 = orthographic), ``L``, ``L_slope`` and ``L_ref`` are held fixed (``fixed=PROFILE_FIXED``; the pipeline fits ``L``).

Jacobian.  The columns are computed in the same pass as the intensity (13 columns for about three times the
cost of the intensity; ``jax.jacfwd`` took 13 times) and are the derivative of the quadrature *as computed*
(the same nodes and weights): the integrand differentiated at fixed nodes, plus the move of the nodes with the
window's ends :math:`v_{0,1}`, which depend on ``d``, ``R``, :math:`\sigma_e` and, through the terminator's cut,
on :math:`\cos\psi'`, :math:`\alpha_0` and the phase (the rule's derivative in its ends:
:func:`~jaxlimb.models.blur_quadrature.window_terms`).  ``jaxlimb gradcheck`` checks the columns against
``jax.jacfwd`` of the intensity at the fits' 20 nodes.

Widened (:data:`LIMB_PROFILE_MINNAERT`, :class:`MinnaertProfileParams`): the radiance times
:math:`(\mu_0\mu)^{-\kappa}`, at ``L = 0`` Minnaert's law :math:`\mu_0^k\mu^{k-1}` with :math:`k = 1 - \kappa`
(Minnaert 1941); its rim diverges as :math:`\mu^{-\kappa}`, brighter than any lunar-Lambert rim.  The
derivative in :math:`\kappa` is :math:`-\ln(\mu_0\mu) I`; the pipeline frees :math:`\kappa` only when a score
test asks for it (:func:`jaxlimb.pipeline.profile.widen.widen_brightening`).

Widened (:data:`LIMB_PROFILE_GLOW`, :class:`GlowProfileParams`): plus a glow above the limb, an optically thin
shell whose emission falls as :math:`e^{-h/H}` with the altitude (a horizon glow of dust or an exosphere; the
``glow`` family of :mod:`jaxlimb.render.independent`): ``glow`` times :math:`e^{-s/H}` at a distance ``s`` above the
limb, and times half the grazing column, :math:`\tfrac12\mathrm{erfcx}(\sqrt{u/H})`, at a depth ``u`` on the disc
(:func:`~jaxlimb.models.profile_glow.glow_inside`, :func:`~jaxlimb.models.profile_glow.glow_outside`); ``H = exp(log_h)`` px.  The disc side is integrated with the
radiance; the sky side blurred in closed form.  The pipeline adds the glow only when a score test asks for it
(:func:`jaxlimb.pipeline.profile.glow.widen_glow`).  The shell is lit by the Sun: at the limb point of image
position angle :math:`\psi` from the Sun's image direction the solar elevation over the tangent point is
:math:`\sin^{-1}(\sin\alpha\cos\psi)` (phase :math:`\alpha`), so the glow is brighter toward the Sun.  To first
order in ``cpsi`` :math:`= \cos\psi` its radiance is ``glow (1 + glow_tilt cpsi)`` (``glow_tilt`` fitted; 0 is a
uniform glow): a glow lit by the Sun but fitted as uniform pulls the centre sunward (``benchmarks/earth_full_disc.py``).

Off the optical axis the limb is an ellipse (``a - b`` reaches ~5 px at the corner of the
default imager for the Moon at 60 000 km): the model carries the ellipse ``(r0, c0, a, theta,
rho)``; with a camera, ``theta`` and ``rho`` are held at the values of the image of a sphere
at the current estimate and iterated, exactly as the sigmoid's body-centre correction
(:func:`jaxlimb.pipeline.sphere.fits.fit_sphere_annulus`), and ``(r0, c0, a)`` map exactly to the
body centre (:func:`jaxlimb.geometry.sphere_image.sphere_from_ellipse_center`).  Without a camera
``rho = 1`` (a circle of radius ``a``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._programs import stored_jit
from ._base import LimbModel, fused_model
from .blur_quadrature import blur_moments, blur_nodes, blur_window, curvature_blur, quadrature_nodes, window_terms
from .profile_glow import glow_inside, glow_outside
from .profile_params import (PHYSICAL_L, PROFILE_FIXED, AnisoProfileParams, GlowProfileParams, LimbProfileParams,
                             MinnaertProfileParams, glow_fields, lunar_lambert_slope, lunar_lambert_weight)
from .profile_radiance import WINDOW_KEYS, aniso_terms_of, aniso_var, limb_geometry, radiance_parts, window_regime


def _add_window(parts: dict, terms, dv0, dv1, scale=1.0, keys: int = len(WINDOW_KEYS)) -> None:
    """``parts["F_<key>"] += scale (D0 dv0/dkey + D1 dv1/dkey)`` for the first ``keys`` of the window's keys
    (``terms = (D0, D1)``, ``dv0, dv1``: ``(6, n)``)."""
    for i, k in enumerate(WINDOW_KEYS[:keys]):
        name = "F_a0" if k == "a0" else ("F_ph" if k == "ph" else f"F_{k}")
        parts[name] = parts[name] + scale * (terms[0] * dv0[i] + terms[1] * dv1[i])


def _glow_integrals(p: GlowProfileParams, d, R, se, cpsi, s2d, derivatives: bool) -> dict:
    """The glow's part of the blurred profile (times its radiance ``gl`` at this position angle): on the disc by the
    quadrature on the uncut window, above the limb in closed form; with ``derivatives`` its partials' pieces."""
    gl = p.glow * (1.0 + p.glow_tilt * cpsi)  # the glow at this position angle (GlowProfileParams)
    win = blur_window(d, R, se, None, derivatives)
    nodes = blur_nodes(d, R, se, win[0], win[1])
    t, g = nodes[1], nodes[3]
    inside = glow_inside(p, nodes[0], node=derivatives)
    G = blur_moments(inside[0], t, g, se, d, derivatives)
    Go, Po = glow_outside(p, d - R, se, d, derivatives)
    out = {"gl": gl, "F1": gl * G.F1, "F1_d": gl * G.F1_d, "F": gl * Go}
    if not derivatives:
        return out
    tg = t * g / jnp.asarray(se)[..., None]
    lh, lh_d = jnp.sum(inside[1] * g, axis=-1), -jnp.sum(inside[1] * tg, axis=-1)
    out.update(F1_dd=gl * G.F1_dd, F1_dse=gl * G.F1_dse, unit=G.F + Go, F_lh=gl * (lh + s2d * lh_d + Po["G_lh"]),
               Po=Po, terms=window_terms(inside[0], inside[2], G.F, nodes, se, s2d, win[0], win[1]), dv0=win[2],
               dv1=win[3])
    return out


def _radiance_partials(rad, nodes, se, s2d, d, F1_d, F1_dd, F1_dse) -> dict:
    """The partials of ``F = F1 + s2d dF1/dd`` at fixed nodes (the integrands differentiated; module docstring of
    :func:`profile_integrals`)."""
    _, I_R, I_cpsi, I_a0, I_ph, I_L, I_k, _, I_s, I_ref = rad
    t, g = nodes[1], nodes[3]
    tg = t * g / jnp.asarray(se)[..., None]  # -dg/dd

    def pair(J):  # (integral of J g, of -J tg): a partial of F1 and the matching partial of F1_d
        return jnp.sum(J * g, axis=-1), -jnp.sum(J * tg, axis=-1)

    F1_R, F1_dR = pair(I_R)
    F1_cp, F1_dcp = pair(I_cpsi)
    F1_a0, F1_da0 = pair(I_a0)
    F1_ph, F1_dph = pair(I_ph)
    F1_L, F1_dL = pair(I_L)
    F1_k, F1_dk = pair(I_k)
    F1_s, F1_ds = pair(I_s)
    F1_ref, F1_dref = pair(I_ref)
    return {
        "F_d": F1_d + s2d * (F1_dd - F1_d / d),
        "F_R": (-F1_d + F1_R) + s2d * (-F1_dd + F1_dR),
        "F_cpsi": F1_cp + s2d * F1_dcp,
        "F_se": F1_dd * se + s2d * F1_dse + se / d * F1_d,  # dg/dse = se d^2g/dd^2 (the heat equation)
        "F_a0": F1_a0 + s2d * F1_da0,
        "F_ph": F1_ph + s2d * F1_dph,
        "F_L": F1_L + s2d * F1_dL,
        "F_k": F1_k + s2d * F1_dk,
        "F_s": F1_s + s2d * F1_ds,
        "F_ref": F1_ref + s2d * F1_dref,
    }


def profile_integrals(p: LimbProfileParams, d, R, cpsi, derivatives: bool, brightened: bool = True,
                      glowing: bool = False, s2=None, window: bool = True):
    """The blurred profile ``F`` (module docstring) and, if asked, its partials.

    ``F = F1 + sigma_e^2 / (2 d) dF1/dd``: the 1-D radial blur ``F1`` plus the first-order
    curvature term of the 2-D blur of a round edge (the ``(1/r) d/dr`` part of the Laplacian:
    the blurred disc's edge moves inward by ``sigma_e^2 / 2R``, 0.02 px for ``R = 33 px``,
    ``sigma = 1.2 px``).  Partials ``F_d, F_R`` (at fixed ``d``/``R``), ``F_cpsi, F_se, F_a0,
    F_ph, F_L, F_k, F_s, F_ref``: the integrands differentiated at fixed nodes plus the move of the nodes with the window's
    ends (:func:`~jaxlimb.models.blur_quadrature.window_terms`).  ``brightened``: as :func:`~jaxlimb.models.profile_radiance.radiance_parts`.
    ``glowing`` (:class:`GlowProfileParams`): plus ``p.glow`` times the glow on the disc side (in the integrand) and
    above the limb (closed form); partials ``F_glow``, ``F_tilt``, ``F_lh``.  ``s2``: the per-pixel anisotropic
    variance of :class:`AnisoProfileParams`, added to ``sigma_e^2``.  ``window=False``: without the window's terms
    (for a column that does not need them: ``F_k``).

    Parameters
    ----------
    p : LimbProfileParams
        The profile's parameters (any of its variants).
    d, R, cpsi : jax.Array (n,)
        Per pixel: distance from the centre and limb radius along its ray (px), cosine of its angle from the Sun's
        image direction (:func:`limb_geometry`).
    derivatives, brightened, glowing, window : bool
        Whether to return the partials; the other switches as above.
    s2 : jax.Array (n,), optional
        Anisotropic blur variance (px^2), as above.

    Returns
    -------
    F : jax.Array (n,)
        The blurred profile, units of ``amp``.
    parts : dict of str to jax.Array, or None
        With ``derivatives``: the partials named above plus ``alpha0`` (rad) and ``se`` (px); ``None`` otherwise.
    """
    alpha0 = jnp.arctan(p.rho * p.a * p.inv_f)
    se = jnp.sqrt(p.sigma * p.sigma + 1.0 / 12.0 + (0.0 if s2 is None else s2))
    win = blur_window(d, R, se, (p, cpsi, alpha0), derivatives and window)
    if derivatives and window:
        win = jax.lax.optimization_barrier(win)  # the ends' partials: once per pixel, not once per column
    nodes = blur_nodes(d, R, se, win[0], win[1])
    rad = radiance_parts(p, nodes[0], R[..., None], cpsi[..., None], alpha0, brightened)
    S, F1, F1_d, F1_dd, F1_dse = blur_moments(rad[0], nodes[1], nodes[3], se, d, derivatives)  # S: the radiance's F
    s2d = se * se / (2.0 * d)
    glow = _glow_integrals(p, d, R, se, cpsi, s2d, derivatives) if glowing else None
    F = S
    if glow is not None:
        F1, F1_d = F1 + glow["F1"], F1_d + glow["F1_d"]
        F = curvature_blur(F1, F1_d, se, d) + glow["F"]
    if not derivatives:
        return F, None
    if glow is not None:
        F1_dd, F1_dse = F1_dd + glow["F1_dd"], F1_dse + glow["F1_dse"]
    parts = _radiance_partials(rad, nodes, se, s2d, d, F1_d, F1_dd, F1_dse)
    if window:
        _add_window(parts, window_terms(rad[0], rad[7], S, nodes, se, s2d, win[0], win[1]), win[2], win[3])
    if glow is not None:
        _add_glow(parts, glow, p, cpsi)
    # computed once per pixel and read by every column (XLA would repeat the window's terms in each column's fusion)
    return jax.lax.optimization_barrier((F, {**parts, "alpha0": alpha0, "se": se}))


def _add_glow(parts: dict, glow: dict, p: GlowProfileParams, cpsi) -> None:
    """The glow's terms of the partials (:func:`_glow_integrals`): its own columns, its closed form's partials,
    its dependence on ``cpsi`` and its window's ends."""
    gl, unit, Po = glow["gl"], glow["unit"], glow["Po"]
    parts["F_glow"] = (1.0 + p.glow_tilt * cpsi) * unit
    parts["F_tilt"] = p.glow * cpsi * unit
    parts["F_cpsi"] = parts["F_cpsi"] + p.glow * p.glow_tilt * unit
    parts["F_lh"] = glow["F_lh"]
    parts["F_d"] = parts["F_d"] + gl * Po["G_d"]
    parts["F_R"] = parts["F_R"] + gl * Po["G_R"]
    parts["F_se"] = parts["F_se"] + gl * Po["G_se"]
    _add_window(parts, glow["terms"], glow["dv0"], glow["dv1"], scale=gl, keys=3)  # the uncut window: d, R, se


def limb_profile_intensity(p: LimbProfileParams, rc):
    """Blurred limb radiance (module docstring) at pixels ``rc`` ``(n, 2)``.

    Along the ray from the ellipse centre through a pixel at distance ``d``, the limb is at
    ``R = rho a d / beta`` (``beta = sqrt(rho^2 x^2 + y^2)`` in the ellipse frame of
    :func:`jaxlimb.models.ellipse_coords`); the circle formulas apply with that ``R``.

    Parameters
    ----------
    p : LimbProfileParams
        The profile's parameters, or those of a widened variant (Minnaert, glow, anisotropic blur).
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,)
        Model intensity ``ymin + amp F`` at each pixel.
    """
    dr, dc, _, _, d, _, R, cpsi = limb_geometry(p, rc)
    F, _ = profile_integrals(p, d, R, cpsi, False, isinstance(p, MinnaertProfileParams),
                              isinstance(p, GlowProfileParams), aniso_var(p, aniso_terms_of(p, dr, dc, d)))
    return p.ymin + p.amp * F


@stored_jit
def brightening_column(p: LimbProfileParams, rc):
    r"""The column of ``kappa`` (:class:`MinnaertProfileParams`) at ``kappa = 0``: the derivative of the
    profile ``p`` toward Minnaert-like limb brightening, for a score test (the whole brightened Jacobian
    costs 2.5x the profile's; this column alone, about one intensity).

    Parameters
    ----------
    p : LimbProfileParams
        The fitted profile.
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.

    Returns
    -------
    jax.Array (n,)
        :math:`\partial f/\partial\kappa` at each pixel.
    """
    _, _, _, _, d, _, R, cpsi = limb_geometry(p, rc)
    _, P = profile_integrals(p, d, R, cpsi, True, False, window=False)
    return p.amp * P["F_k"]


def _profile_value_and_columns(p: LimbProfileParams, rc):
    """Intensity and all Jacobian columns from one pass (the quadrature's derivative; module docstring).

    The chain rule from the per-pixel quantities ``(d, R, cpsi, se, alpha0)`` to the
    parameters is written out; checked against ``jax.jacfwd`` of :func:`limb_profile_intensity`
    in ``tests/pipeline/test_profile.py``.
    """
    dr, dc, x, y, d, beta, R, cpsi = limb_geometry(p, rc)
    brightened = isinstance(p, MinnaertProfileParams)
    glowing = isinstance(p, GlowProfileParams)
    aniso = aniso_terms_of(p, dr, dc, d)
    F, P = profile_integrals(p, d, R, cpsi, True, brightened, glowing, aniso_var(p, aniso))
    A = p.amp
    ct, st = jnp.cos(p.theta), jnp.sin(p.theta)
    # d/dr0, d/dc0 of d, beta, R, cpsi
    d_r0, d_c0 = -dr / d, -dc / d
    x_r0, x_c0, y_r0, y_c0 = st, -ct, ct, st
    rho2 = p.rho * p.rho
    b_r0 = (rho2 * x * x_r0 + y * y_r0) / beta
    b_c0 = (rho2 * x * x_c0 + y * y_c0) / beta
    R_r0 = R * (d_r0 / d - b_r0 / beta)
    R_c0 = R * (d_c0 / d - b_c0 / beta)
    cp_r0 = (-p.sun_r - cpsi * d_r0) / d
    cp_c0 = (-p.sun_c - cpsi * d_c0) / d
    # theta: x_th = -y... (x, y rotate with theta): dx/dtheta = y, dy/dtheta = -x
    b_th = (rho2 * x * y - y * x) / beta
    R_th = -R * b_th / beta
    R_rho = R / p.rho - R * (p.rho * x * x) / (beta * beta)
    u = p.rho * p.a * p.inv_f
    a0_common = 1.0 / (1.0 + u * u)
    F_d, F_R, F_cp, F_a0 = P["F_d"], P["F_R"], P["F_cpsi"], P["F_a0"]
    cols = {
        "r0": A * (F_d * d_r0 + F_R * R_r0 + F_cp * cp_r0),
        "c0": A * (F_d * d_c0 + F_R * R_c0 + F_cp * cp_c0),
        "a": A * (F_R * R / p.a + F_a0 * a0_common * p.rho * p.inv_f),
        "theta": A * F_R * R_th,
        "rho": A * (F_R * R_rho + F_a0 * a0_common * p.a * p.inv_f),
        "sigma": A * P["F_se"] * p.sigma / P["se"],
        "amp": F,
        "ymin": jnp.ones_like(F),
        "sun_r": A * F_cp * dr / d,
        "sun_c": A * F_cp * dc / d,
        "phase": A * P["F_ph"],
        "inv_f": A * F_a0 * a0_common * p.rho * p.a,
        "L": A * P["F_L"],
        "L_slope": A * P["F_s"],
        "L_ref": A * P["F_ref"],
        "kappa": A * P["F_k"],
    }
    if glowing:
        cols.update(glow=A * P["F_glow"], log_h=A * P["F_lh"], glow_tilt=A * P["F_tilt"])
    if aniso is not None:  # d sigma_e / d s2 = (cos 2psi or sin 2psi) / (2 sigma_e); psi moves with r0, c0
        C, S, C_r0, C_c0, S_r0, S_c0 = aniso
        ws = A * P["F_se"] / (2.0 * P["se"])
        cols.update(r0=cols["r0"] + ws * (p.s2c * C_r0 + p.s2s * S_r0), c0=cols["c0"] + ws * (p.s2c * C_c0 + p.s2s * S_c0),
                    s2c=ws * C, s2s=ws * S)
    return p.ymin + A * F, tuple(cols[n] for n in type(p).field_names())


LIMB_PROFILE = fused_model("lunar_limb", LimbProfileParams, limb_profile_intensity, _profile_value_and_columns)
"""The physical lunar-Lambert limb profile model (circle geometry)."""
LIMB_PROFILE_MINNAERT = fused_model("lunar_limb_minnaert", MinnaertProfileParams, limb_profile_intensity,
                                    _profile_value_and_columns)
"""The profile widened by a limb-brightening exponent ``kappa`` (:class:`MinnaertProfileParams`)."""
LIMB_PROFILE_GLOW = fused_model("lunar_limb_glow", GlowProfileParams, limb_profile_intensity,
                                _profile_value_and_columns)
"""The profile widened by an exponential glow above the limb (:class:`GlowProfileParams`)."""
LIMB_PROFILE_ANISO = fused_model("lunar_limb_aniso", AnisoProfileParams, limb_profile_intensity,
                                 _profile_value_and_columns)
"""The profile with an anisotropic blur (:class:`AnisoProfileParams`: a motion smear)."""


def profile_model(p: LimbProfileParams) -> LimbModel:
    """The profile model of the parameters ``p``: :data:`LIMB_PROFILE_MINNAERT`, :data:`LIMB_PROFILE_GLOW` or
    :data:`LIMB_PROFILE_ANISO` or :data:`LIMB_PROFILE`.

    Parameters
    ----------
    p : LimbProfileParams
        Parameters of any profile variant.

    Returns
    -------
    LimbModel
        The model whose ``params_type`` is the type of ``p``.
    """
    if isinstance(p, MinnaertProfileParams):
        return LIMB_PROFILE_MINNAERT
    if isinstance(p, AnisoProfileParams):
        return LIMB_PROFILE_ANISO
    return LIMB_PROFILE_GLOW if isinstance(p, GlowProfileParams) else LIMB_PROFILE


__all__ = ["LIMB_PROFILE", "LIMB_PROFILE_ANISO", "AnisoProfileParams", "LIMB_PROFILE_GLOW", "LIMB_PROFILE_MINNAERT",
           "GlowProfileParams", "LimbProfileParams", "MinnaertProfileParams", "blur_nodes", "blur_window",
           "brightening_column", "glow_fields", "limb_geometry", "PHYSICAL_L", "PROFILE_FIXED", "limb_profile_intensity",
           "lunar_lambert_slope", "lunar_lambert_weight", "profile_integrals", "profile_model", "quadrature_nodes",
           "window_regime"]
