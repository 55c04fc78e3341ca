"""The blur integral's quadrature of the physical limb profile (:mod:`jaxlimb.models.blur_quadrature`)."""

import jax
import jax.numpy as jnp
import numpy as np
from scipy.stats import norm

from jaxlimb.models.blur_quadrature import blur_moments, blur_nodes, blur_window, quadrature_nodes

jax.config.update("jax_enable_x64", True)


def _nodes(se):
    d = jnp.linspace(93.0, 107.0, 57)  # across the limb at R = 100 px, deep inside to past the window
    R = jnp.full_like(d, 100.0)
    v, t, _, g = blur_nodes(d, R, se, *blur_window(d, R, se))
    return d, R, v, t, g


def test_a_uniform_radiance_blurs_to_the_gaussian_step_with_its_curvature_term():
    """For ``J = 1`` the blur is the Gaussian's CDF of the depth, ``F1 = Phi((R - d) / se)``, its derivatives
    ``-N(d - R; se)`` and ``(d - R) / se^2 N``, and ``F = F1 + se^2/(2d) dF1/dd``, to the window's cut at six
    sigma (~1e-8) with 96 nodes (the fits' 20 against 96: ``tests/pipeline/test_profile.py``)."""
    se = 1.3
    with quadrature_nodes(96):
        d, R, v, t, g = _nodes(se)
        m = blur_moments(jnp.ones_like(v), t, g, se, d, second=True)
    x = np.asarray(d - R)
    F1, F1_d, F1_dd = norm.cdf(-x / se), -norm.pdf(x, scale=se), x / se**2 * norm.pdf(x, scale=se)
    np.testing.assert_allclose(m.F1, F1, atol=3e-8)
    np.testing.assert_allclose(m.F1_d, F1_d, atol=3e-8)
    np.testing.assert_allclose(m.F1_dd, F1_dd, atol=3e-8)
    np.testing.assert_allclose(m.F, F1 + se * se / (2.0 * np.asarray(d)) * F1_d, atol=3e-8)


def test_moments_over_a_partition_of_unity_sum_to_the_moments():
    """A basis of hats that sums to one at every node splits the blur: its moments add up to the plain ones, with
    one sigma for all pixels or one per pixel."""
    for se in (0.9, jnp.linspace(0.6, 1.4, 57)):
        d, R, v, t, g = _nodes(se)
        J = 1.0 + 0.3 * jnp.sin(v)
        hats = jnp.maximum(0.0, 1.0 - jnp.abs(v[..., None] / 1.5 - jnp.arange(4)))
        whole, split = blur_moments(J, t, g, se, d), blur_moments(J, t, g, se, d, basis=hats)
        assert split.F.shape == (57, 4)
        for a, b in zip(whole[:3], split[:3]):
            np.testing.assert_allclose(np.asarray(b).sum(-1), a, rtol=1e-12, atol=1e-14)
