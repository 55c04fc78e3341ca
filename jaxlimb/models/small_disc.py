r"""The image of a few-pixel sunlit sphere: its lit disc, blurred by the PSF and integrated over the pixels.

Why.  Below a radius of ~10 px there is no limb to fit: the PSF is as wide as the disc's rim, and at radii of 1-3 px
the body is a blob whose centre of brightness lies sunward of the body centre by a fraction of the radius (the phase
offset, GIANT's "phase correction").  This model is the whole blob: a sphere's lit disc at the known phase, so that
its centre ``(r0, c0)`` is the image of the body centre and the phase offset is in the model, not in the answer.

Radiance (orthographic: the body subtends a few pixels).  A point of the disc at ``(dy, dx) / a`` from its centre
(``a`` the apparent radius, px) has the normal :math:`n = (x, y, \sqrt{1 - x^2 - y^2})` (``x`` toward ``+col``, ``y``
toward ``+row``, ``z`` toward the observer), :math:`\mu = n_z`, and with the Sun at phase :math:`\vartheta` in the
image direction ``(sun_r, sun_c)``,

.. math:: \mu_0 = \sin\vartheta\,(x\,s_c + y\,s_r) + \cos\vartheta\,\mu,\qquad
          I = L\,\frac{2\mu_0}{\mu_0 + \mu} + (1 - L)\,\mu_0 \quad (\mu_0 > 0),

the lunar-Lambert law of :mod:`jaxlimb.models.lunar_lambert` (McEwen 1996).

Image.  The radiance is sampled on a grid of ``N_SUB x N_SUB`` cells of side ``grid_h`` about ``(grid_r, grid_c)``
(fixed: the start), each cell weighted by the fraction of it inside the disc (a linear ramp across the limb over one
cell: the edge's first moment is exact, so the disc's centre and area are), and the PSF (a Gaussian of ``sigma``) and
the pixel's box are applied exactly per cell: the pixel-integrated Gaussian
:math:`G(x) = \tfrac12[\mathrm{erf}((x + \tfrac12)/\sqrt2\sigma) - \mathrm{erf}((x - \tfrac12)/\sqrt2\sigma)]`
separates in rows and columns, so the window of ``WINDOW x WINDOW`` pixels at ``(win_r, win_c)`` is
:math:`y_{\min} + A\,G_r S G_c^\top`.  Cost: two small matrix products, whatever the radius.

Parameters ``(r0, c0, a, sigma, amp, ymin, L)`` are estimated (``a`` and ``L`` held when the range is known and the
disc is not resolved): the law's weight ``L`` is the surface's own limb darkening, which another law (Hapke, Minnaert)
gives a different value than the phase's lunar-Lambert fit, and held at that value it moves ``a`` and the centre;
``sun_r, sun_c, phase`` (geometry), ``win_r, win_c`` (window) and ``grid_r, grid_c, grid_h`` (sample grid) are held
(:data:`SMALL_DISC_FIXED`).  The Jacobian is ``jax.jacfwd`` of the intensity (autodiff through the
grid: the derivative of the discretised image, which is the image the fit compares with the data).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax.scipy.special import erf
from jaxtyping import ArrayLike

from ._base import LimbModel, LimbParams

#: Cells of the radiance grid along each axis: the model's phase offset within 0.006 px of the exact (supersampled,
#: perspective) renders' for radii 1-3 px at phases 5-85 deg (0.014 px with 96 cells).
N_SUB = 192
#: Side (px) of the square window of pixels the model predicts.
WINDOW = 40
#: Floor (px) added in quadrature to ``sigma``: keeps the pixel box's edges differentiable at ``sigma = 0``.
SIGMA_FLOOR = 0.05
#: Parameters held by default (geometry, window, grid).
SMALL_DISC_FIXED = ("sun_r", "sun_c", "phase", "win_r", "win_c", "grid_r", "grid_c", "grid_h")


class SmallDiscParams(LimbParams):
    """Parameters of :func:`small_disc_intensity` (module docstring)."""

    r0: ArrayLike
    c0: ArrayLike
    a: ArrayLike
    sigma: ArrayLike
    amp: ArrayLike
    ymin: ArrayLike
    sun_r: ArrayLike
    sun_c: ArrayLike
    phase: ArrayLike
    L: ArrayLike
    win_r: ArrayLike
    win_c: ArrayLike
    grid_r: ArrayLike
    grid_c: ArrayLike
    grid_h: ArrayLike


def grid_half_extent(a: float) -> float:
    """Half-side (px) of the radiance grid for a disc of radius ``a``: room for the radius to grow by a quarter and
    the centre to move by 1.5 px from the start.

    Parameters
    ----------
    a : float
        Apparent radius (px) of the disc at the start.

    Returns
    -------
    float
        Half-side (px) of the grid; ``grid_h`` is twice this over ``N_SUB``.
    """
    return 1.25 * float(a) + 1.5


@jax.jit
def radiance_grid(p: SmallDiscParams):
    """Cell centres ``(ys, xs)`` (px) and the radiance times the covered area of each cell, ``(N_SUB, N_SUB)``.

    Parameters
    ----------
    p : SmallDiscParams
        The model's parameters (module docstring).

    Returns
    -------
    ys, xs : jax.Array
        Row and column coordinates (px) of the cell centres, ``(N_SUB,)`` each.
    S : jax.Array
        Lunar-Lambert radiance (1 at normal incidence and emission) times the area (px^2) of each cell inside the disc,
        ``(N_SUB, N_SUB)``.
    """
    h = p.grid_h
    k = (jnp.arange(N_SUB) + 0.5 - 0.5 * N_SUB) * h
    ys, xs = p.grid_r + k, p.grid_c + k
    dy = (ys - p.r0)[:, None] / p.a
    dx = (xs - p.c0)[None, :] / p.a
    q2 = dy * dy + dx * dx
    q = jnp.sqrt(jnp.maximum(q2, 1e-30))
    cover = jnp.clip(0.5 - (q - 1.0) * p.a / h, 0.0, 1.0)
    inv = jnp.where(q > 1.0, 1.0 / q, 1.0)  # the rim's partly covered cells take the limb's radiance
    x, y = dx * inv, dy * inv
    mu = jnp.sqrt(jnp.maximum(1.0 - (x * x + y * y), 1e-9))
    mu0 = jnp.sin(p.phase) * (x * p.sun_c + y * p.sun_r) + jnp.cos(p.phase) * mu
    lit = mu0 > 0.0
    m0 = jnp.where(lit, mu0, 0.0)
    rad = jnp.where(lit, p.L * 2.0 * m0 / jnp.where(lit, m0 + mu, 1.0) + (1.0 - p.L) * m0, 0.0)
    return ys, xs, rad * cover * h * h


def pixel_gaussian(x, sigma):
    """The Gaussian of ``sigma`` integrated over a pixel of unit width centred ``x`` away (module docstring).

    Parameters
    ----------
    x : array_like
        Offsets (px) of the pixel centres from the Gaussian's centre.
    sigma : array_like
        PSF standard deviation (px); ``SIGMA_FLOOR`` is added in quadrature.

    Returns
    -------
    jax.Array
        The fraction of the Gaussian's mass in each pixel, shaped like ``x``.
    """
    s = jnp.sqrt(2.0) * jnp.sqrt(sigma * sigma + SIGMA_FLOOR * SIGMA_FLOOR)
    return 0.5 * (erf((x + 0.5) / s) - erf((x - 0.5) / s))


def small_disc_window(p: SmallDiscParams):
    """The model over the whole ``WINDOW x WINDOW`` window, without ``ymin`` and ``amp``.

    Parameters
    ----------
    p : SmallDiscParams
        The model's parameters (module docstring).

    Returns
    -------
    jax.Array
        The PSF-blurred, pixel-integrated disc ``G_r S G_c^T``, ``(WINDOW, WINDOW)``; row ``i``, column ``j`` is
        the pixel ``(win_r + i, win_c + j)``.
    """
    ys, xs, S = radiance_grid(p)
    rows = p.win_r + jnp.arange(WINDOW)
    cols = p.win_c + jnp.arange(WINDOW)
    Gr = pixel_gaussian(rows[:, None] - ys[None, :], p.sigma)
    Gc = pixel_gaussian(cols[:, None] - xs[None, :], p.sigma)
    return Gr @ S @ Gc.T


def small_disc_intensity(p: SmallDiscParams, rc):
    """The model (module docstring) at pixels ``rc`` ``(n, 2)`` of the window.

    Parameters
    ----------
    p : SmallDiscParams
        The model's parameters (module docstring).
    rc : array_like
        Pixel coordinates ``(n, 2)`` (row, column; px) inside the window; rounded and clipped to it.

    Returns
    -------
    jax.Array
        The predicted intensity ``ymin + amp * M`` (DN) at each pixel, ``(n,)``.
    """
    rc = jnp.asarray(rc)
    M = small_disc_window(p)
    ir = jnp.clip(jnp.round(rc[..., 0] - p.win_r), 0, WINDOW - 1).astype(jnp.int32)
    ic = jnp.clip(jnp.round(rc[..., 1] - p.win_c), 0, WINDOW - 1).astype(jnp.int32)
    return p.ymin + p.amp * M[ir, ic]


@jax.jit
def _offset(p: SmallDiscParams):
    ys, xs, S = radiance_grid(p)
    tot = jnp.sum(S)
    return jnp.stack([jnp.sum(S * (ys[:, None] - p.r0)) / tot, jnp.sum(S * (xs[None, :] - p.c0)) / tot])


def photocentre_offset(p: SmallDiscParams) -> tuple[float, float]:
    """The centre of brightness of the model's disc minus its centre ``(d_row, d_col)`` (px): the phase offset of a
    moment (centroid) measurement; the PSF, being symmetric, does not move it.

    Parameters
    ----------
    p : SmallDiscParams
        The model's parameters (module docstring).

    Returns
    -------
    tuple of float
        ``(d_row, d_col)`` (px).
    """
    d = _offset(p)
    return float(d[0]), float(d[1])


#: :func:`small_disc_intensity` compiled, for calls outside a fit (the noise model, the residuals).
small_disc_predict = jax.jit(small_disc_intensity)


def _intensity_vec(theta, rc):
    return small_disc_intensity(SmallDiscParams.from_vector(theta), rc)


@jax.jit
def _jacobian(p: SmallDiscParams, rc):
    return jax.jacfwd(_intensity_vec)(p.to_vector(), rc)


def _columns(p: SmallDiscParams, rc):
    J = _jacobian(p, rc)
    return tuple(J[..., i] for i in range(J.shape[-1]))


SMALL_DISC = LimbModel("small_disc", SmallDiscParams, small_disc_intensity, _jacobian, _columns)


def sun_angle_params(sun_rc, phase_rad: float) -> tuple[float, float, float]:
    """``(sun_r, sun_c, phase)`` with a unit image direction (``(1, 0)`` when undefined).

    Parameters
    ----------
    sun_rc : array_like or None
        Image direction ``(row, col)`` toward the Sun, any length; ``None`` or zero when unknown.
    phase_rad : float
        Sun phase angle (rad).

    Returns
    -------
    tuple of float
        ``(sun_r, sun_c, phase)``: the unit direction and the phase (rad), the held parameters of
        :class:`SmallDiscParams`.
    """
    n = math.hypot(float(sun_rc[0]), float(sun_rc[1])) if sun_rc is not None else 0.0
    if n < 1e-12:
        return 1.0, 0.0, float(phase_rad)
    return float(sun_rc[0]) / n, float(sun_rc[1]) / n, float(phase_rad)


__all__ = ["N_SUB", "SMALL_DISC", "SMALL_DISC_FIXED", "SmallDiscParams", "WINDOW", "grid_half_extent",
           "photocentre_offset", "pixel_gaussian", "radiance_grid", "small_disc_intensity", "small_disc_predict",
           "small_disc_window",
           "sun_angle_params"]
