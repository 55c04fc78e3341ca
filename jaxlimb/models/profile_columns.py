r"""Columns of the physical limb profile (:mod:`jaxlimb.models.lunar_lambert`) toward what it does not fit: a glow
above the limb (a score test's column) and an albedo that varies over the surface (a Gaussian nuisance).

Albedo field.  The profile assumes one albedo.  A real surface's albedo varies across the few pixels inside the
limb as well as along it, and a fit with one albedo reads an albedo that darkens toward the limb as an edge moved
inward.  The edge is where the surface ends; the albedo only scales the radiance inside it.  Write the albedo as
:math:`A\,(1 + a)` with :math:`a` a zero-mean random field on the sphere, represented on nodes
:math:`(\theta_m, \psi_n)` (surface angle from the limb, :math:`\theta = \sin^{-1}\mu`, and image position angle
of the ray) by hat functions :math:`h_m(\theta)\,g_n(\psi)`.  The profile is linear in the nodes' values:

.. math:: f_i = f_i^0 + \sum_{mn} K_{i,mn}\, a_{mn}, \qquad
          K_{i,mn} = A_{\mathrm{amp}}\, g_n(\psi_i)\int I(v)\, h_m(\theta(v))\, N(d_i - R_i + v^2; \sigma_e)\,2v\,dv

(the blur integral of :mod:`jaxlimb.models.blur_quadrature` with the radiance times the hat, curvature term included;
the hats sum to one, so :math:`\sum_{mn} K_{i,mn}` is the profile's radiance part).  With a Gaussian prior
:math:`a \sim N(0, C)`, :math:`C_{jk} = \tau^2 \exp(-\gamma_{jk}^2 / 2\ell^2)` (:math:`\gamma` the great-circle
angle between two nodes, the limb taken as the great circle normal to the line of sight), the pixels' covariance
is :math:`\Sigma = D + K C K^\top` and the geometry's information :math:`J^\top\Sigma^{-1}J`: the Bayesian
Cramér--Rao bound with the albedo marginalised (Van Trees 1968, Sec. 2.4), and the weight of the generalised
least-squares fit that attains it.  The nodes are spaced at half of :math:`\ell` in both angles: the hats'
piecewise-linear field then follows a squared-exponential field of length :math:`\ell` to a few per cent.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from .._programs import stored_jit
from .blur_quadrature import blur_moments, blur_nodes, blur_window
from .profile_glow import glow_inside, glow_outside
from .profile_params import GlowProfileParams, LimbProfileParams
from .profile_radiance import limb_geometry, radiance_parts


@stored_jit
def glow_column(p: LimbProfileParams, rc, log_h):
    r"""The column of ``glow`` (:class:`GlowProfileParams`) at ``glow = 0`` and scale height ``exp(log_h)`` px:
    the derivative of the profile ``p`` toward a glow, for a score test (the intensity's cost).

    Parameters
    ----------
    p : LimbProfileParams
        The fitted profile (without a glow).
    rc : jax.Array (n, 2)
        Pixel coordinates as ``(row, col)``.
    log_h : float or jax.Array ()
        Log of the glow's scale height (px).

    Returns
    -------
    jax.Array (n,)
        :math:`\partial f/\partial\,\mathrm{glow}` at each pixel.
    """
    q = GlowProfileParams(*[getattr(p, n) for n in LimbProfileParams.field_names()], 0.0, log_h)
    _, _, _, _, d, _, R, _ = limb_geometry(q, rc)
    se = jnp.sqrt(q.sigma * q.sigma + 1.0 / 12.0)
    v, t, _, g = blur_nodes(d, R, se, *blur_window(d, R, se))
    return q.amp * (blur_moments(glow_inside(q, v)[0], t, g, se, d).F + glow_outside(q, d - R, se, d, False)[0])


def albedo_nodes(p: LimbProfileParams, rc, ell_rad: float) -> tuple[np.ndarray, int]:
    """The albedo field's nodes for a profile ``p`` on pixels ``rc``: surface angles from the limb to the deepest
    pixel's window, and the number of position angles, both spaced at ``ell_rad / 2`` (module docstring).

    Parameters
    ----------
    p : LimbProfileParams
        The profile (its centre, radius and blur).
    rc : array_like (n, 2)
        Pixel coordinates as ``(row, col)``.
    ell_rad : float
        The prior's correlation length (rad).

    Returns
    -------
    theta : numpy.ndarray (m,)
        Surface angles from the limb (rad), from 0.
    n_psi : int
        Position-angle nodes around the limb.
    """
    rc = np.asarray(rc, float)
    step = ell_rad / 2.0
    depth = float(p.a) - float(np.min(np.hypot(rc[:, 0] - float(p.r0), rc[:, 1] - float(p.c0))))
    depth += 6.0 * math.sqrt(float(p.sigma) ** 2 + 1.0 / 12.0)
    th_max = math.asin(min(1.0, math.sqrt(max(depth, 0.0) * (2.0 * float(p.a) - depth)) / float(p.a)))
    return np.arange(int(math.ceil(th_max / step)) + 1) * step, max(int(math.ceil(2.0 * math.pi / step)), 3)


def node_bucket(m: int) -> int:
    """Padded number of surface-angle nodes for ``m``: the next of 2, 3, 4, 6, 8, 12, 16, ... (a limb's depth in
    nodes changes with every frame's radius; a program per bucket, not per depth, wasting at most half).

    Parameters
    ----------
    m : int
        Nodes.

    Returns
    -------
    int
    """
    b = 2
    while b < m:
        b = b * 3 // 2 if b & (b - 1) == 0 else b * 4 // 3
    return b


@stored_jit
def _padded_parts(p: LimbProfileParams, rc, step, m, m_onehot, n_psi_onehot):
    """The two factors of :func:`albedo_field_columns`, ``K_{i,mn} = F_im B_in``: ``F`` ``(n, len(m_onehot))`` on the
    surface-angle nodes ``j * step`` (those from ``m`` on zero; the amplitude in it) and the position-angle hats ``B``
    ``(n, len(n_psi_onehot))``."""
    dr, dc, _, _, d, _, R, cpsi = limb_geometry(p, rc)
    alpha0 = jnp.arctan(p.rho * p.a * p.inv_f)
    se = jnp.sqrt(p.sigma * p.sigma + 1.0 / 12.0)
    v, t, _, g = blur_nodes(d, R, se, *blur_window(d, R, se, (p, cpsi, alpha0)))
    I = radiance_parts(p, v, R[..., None], cpsi[..., None], alpha0, False)[0]
    q = jnp.clip(1.0 - v * v / R[..., None], 0.0, 1.0)
    th = jnp.arcsin(jnp.clip(v * jnp.sqrt((1.0 + q) / R[..., None]), 0.0, 1.0))[..., None]
    j = jnp.arange(m_onehot.shape[0])
    H = jnp.where(j < m, jnp.maximum(0.0, 1.0 - jnp.abs(th / step - j)), 0.0)
    H = jnp.where((j == m - 1) & (th >= (m - 1) * step), 1.0, H)  # the last hat holds the deepest angles
    F = blur_moments(I, t, g, se, d, basis=H).F
    k = n_psi_onehot.shape[0]
    x = (jnp.arctan2(-dr, dc) % (2.0 * jnp.pi)) * (k / (2.0 * jnp.pi))
    B = jnp.maximum(0.0, 1.0 - jnp.abs((x[:, None] - jnp.arange(k) + k / 2.0) % k - k / 2.0))
    return p.amp * F, B


def _parts(p: LimbProfileParams, rc, theta: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``F`` ``(n, m)`` and ``B`` ``(n, k)`` of :func:`_padded_parts` on the nodes ``theta``, one program per bucket
    of surface-angle nodes (:func:`node_bucket`) and of pixels."""
    m = theta.size
    step = float(theta[1] - theta[0]) if m > 1 else 1.0
    F, B = _padded_parts(p, *jax.device_put((np.asarray(rc, float), np.asarray(step), np.asarray(m),
                                             np.zeros(node_bucket(m)), np.zeros(k))))
    return np.asarray(F)[:, :m], np.asarray(B)


def albedo_field_columns(p: LimbProfileParams, rc, theta, n_psi_onehot) -> np.ndarray:
    r""":math:`K` of the module docstring: the profile's response to the albedo at each node, ``K_{i,mn} = F_im
    B_in`` (the surface-angle part and the position-angle hat).  One program per bucket of surface-angle nodes
    (:func:`node_bucket`) and of pixels.

    Parameters
    ----------
    p : LimbProfileParams
        The profile (lunar-Lambert radiance, no glow or brightening).
    rc : array_like (n, 2)
        Pixel coordinates as ``(row, col)``.
    theta : array_like (m,)
        Node surface angles (rad), evenly spaced from 0 (:func:`albedo_nodes`).
    n_psi_onehot : array_like (k,)
        Any array of length ``k``, the number of position-angle nodes.

    Returns
    -------
    numpy.ndarray (n, m * k)
        Column ``k * m_index + n_index`` is node ``(theta_m, psi_n)``, ``psi_n = 2 pi n / k``.
    """
    theta = np.asarray(theta, float)
    F, B = _parts(p, rc, theta, len(n_psi_onehot))
    return (F[:, :, None] * B[:, None, :]).reshape(F.shape[0], -1)


def albedo_prior_blocks(theta: np.ndarray, n_psi: int, tau: float, ell_rad: float) -> list[tuple[np.ndarray, np.ndarray]]:
    r"""The factor of :func:`albedo_prior_factor` by blocks: its columns are ``kron(W[:, j], u)`` for each
    ``(W, u)`` here, a real Fourier vector ``u`` ``(n_psi,)`` in the position angle and the eigenvectors ``W``
    ``(m, r)`` of the prior's block at its frequency, scaled by the square roots of their eigenvalues.

    The position-angle nodes are evenly spaced, so :math:`C` is block-circulant: the real Fourier vectors in
    :math:`\psi` times the eigenvectors of one ``m x m`` block per frequency diagonalise it (``n_psi`` small
    eigenproblems instead of one of size ``m n_psi``).  Eigenvectors below ``1e-9`` of the largest eigenvalue are left
    out (they add nothing a fit can see), and negative ones with them: the squared exponential of the great-circle
    angle is not positive definite on the sphere for every length (the projection on the positive semidefinite cone).

    Parameters
    ----------
    theta, n_psi, tau, ell_rad
        As :func:`albedo_prior_factor`'s.

    Returns
    -------
    list of (numpy.ndarray (m, r_f), numpy.ndarray (n_psi,))
        In the column order of :func:`albedo_prior_factor`; blocks with no column left out.
    """
    th = np.asarray(theta, float)
    k = int(n_psi)
    dpsi = 2.0 * math.pi * np.arange(k) / k
    cos_g = (np.cos(th)[:, None, None] * np.cos(th)[None, :, None] * np.cos(dpsi)[None, None, :]
             + np.sin(th)[:, None, None] * np.sin(th)[None, :, None])
    c = tau * tau * np.exp(-0.5 * (np.arccos(np.clip(cos_g, -1.0, 1.0)) / ell_rad) ** 2)  # (m, m, lag)
    a = np.arange(k)
    freqs = np.arange(k // 2 + 1)
    ws, Ws = np.linalg.eigh(np.einsum("abl,lf->fab", c, np.cos(2.0 * math.pi * np.outer(a, freqs) / k)))
    floor = 1e-9 * ws.max()
    blocks = []
    for f, w, W in zip(freqs, ws, Ws):  # the blocks' eigenproblems in one batched call
        keep = w > floor
        cf = np.cos(2.0 * math.pi * f * a / k)
        for u in [cf] + ([np.sin(2.0 * math.pi * f * a / k)] if 0 < 2 * f < k else []):
            if keep.any():
                blocks.append((W[:, keep] * np.sqrt(w[keep]), u / np.linalg.norm(u)))
    return blocks


def albedo_prior_factor(theta: np.ndarray, n_psi: int, tau: float, ell_rad: float) -> np.ndarray:
    r"""A factor :math:`F` of the nodes' prior covariance, :math:`C = F F^\top` (module docstring), projected on the
    positive semidefinite cone, from its blocks (:func:`albedo_prior_blocks`).

    Parameters
    ----------
    theta : numpy.ndarray (m,)
        Node surface angles from the limb (rad).
    n_psi : int
        Position-angle nodes.
    tau : float
        The relative albedo's standard deviation.
    ell_rad : float
        Its correlation length (rad).

    Returns
    -------
    numpy.ndarray (m * n_psi, r)
        In the row order of :func:`albedo_field_columns`' columns.
    """
    blocks = albedo_prior_blocks(theta, n_psi, tau, ell_rad)
    return np.concatenate([np.einsum("mr,k->mkr", W, u).reshape(W.shape[0] * u.size, -1) for W, u in blocks], axis=1)


def albedo_prior(theta: np.ndarray, n_psi: int, tau: float, ell_rad: float) -> np.ndarray:
    """The nodes' prior covariance :math:`C` (module docstring): ``F F^T`` of :func:`albedo_prior_factor`.

    Parameters
    ----------
    theta, n_psi, tau, ell_rad
        As :func:`albedo_prior_factor`'s.

    Returns
    -------
    numpy.ndarray (m * n_psi, m * n_psi)
        In the column order of :func:`albedo_field_columns`.
    """
    F = albedo_prior_factor(theta, n_psi, tau, ell_rad)
    return F @ F.T


def albedo_field_factor(p: LimbProfileParams, rc, tau: float, ell_rad: float) -> np.ndarray:
    """``K C^{1/2}`` (module docstring) at the profile ``p``: ``K C K^T`` is its product with its transpose
    (:func:`albedo_prior_factor`).  Formed by blocks without ``K``: with ``K_{i,mn} = F_im B_in`` and the factor's
    columns ``kron(W_j, u)`` (:func:`albedo_prior_blocks`), a column is ``(F W_j)_i (B u)_i``: ``n m r`` operations
    instead of ``n m n_psi r``.

    Parameters
    ----------
    p : LimbProfileParams
        The profile.
    rc : array_like (n, 2)
        Pixel coordinates as ``(row, col)``.
    tau : float
        The relative albedo's standard deviation.
    ell_rad : float
        Its correlation length (rad).

    Returns
    -------
    numpy.ndarray (n, r)
        One column per kept eigenvector of the prior.
    """
    theta, n_psi = albedo_nodes(p, rc, ell_rad)
    F, B = _parts(p, rc, theta, n_psi)
    blocks = albedo_prior_blocks(theta, n_psi, tau, ell_rad)
    Bu = B @ np.stack([u for _, u in blocks], axis=1)  # each block's Fourier vector at the pixels
    return np.concatenate([(F @ W) * Bu[:, i, None] for i, (W, _) in enumerate(blocks)], axis=1)


__all__ = ["albedo_field_columns", "albedo_field_factor", "albedo_nodes", "albedo_prior", "albedo_prior_blocks",
           "albedo_prior_factor", "glow_column", "node_bucket"]
