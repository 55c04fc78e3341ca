"""The albedo field's columns of the physical limb profile and their prior (:mod:`jaxlimb.models.profile_columns`)."""

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxlimb.models import LimbProfileParams, limb_profile_intensity
from jaxlimb.models.profile_columns import (albedo_field_columns, albedo_field_factor, albedo_nodes, albedo_prior,
                                            albedo_prior_factor, node_bucket)

jax.config.update("jax_enable_x64", True)


def _limb(a=60.0, phase=0.8):
    p = LimbProfileParams(r0=300.0, c0=310.0, a=a, theta=0.0, rho=1.0, sigma=0.9, amp=1000.0, ymin=5.0, sun_r=0.6,
                          sun_c=0.8, phase=phase, inv_f=1e-4, L=0.5, L_slope=-1.0, L_ref=0.6)
    ang = np.linspace(0.0, 2.0 * math.pi, 360, endpoint=False)
    rr = np.linspace(a - 6.0, a + 6.0, 13)
    g = np.stack(np.meshgrid(ang, rr), -1).reshape(-1, 2)
    return p, np.column_stack([300.0 + g[:, 1] * np.sin(g[:, 0]), 310.0 + g[:, 1] * np.cos(g[:, 0])])


def test_albedo_columns_sum_to_the_profile_and_each_answers_near_its_node():
    """The hats partition unity, so a uniform change of albedo (every node's value 1) is the profile's radiance
    part exactly; and a node's column is zero on rays more than one position-angle step from it."""
    p, rc = _limb()
    theta, n_psi = albedo_nodes(p, rc, math.radians(10.0))
    depth = 6.0 + 6.0 * math.sqrt(0.81 + 1.0 / 12.0)  # the deepest pixel's blur window
    assert theta[0] == 0.0 and theta[-1] >= math.asin(math.sqrt(depth * (2 * 60 - depth)) / 60) > theta[-2]
    K = np.asarray(albedo_field_columns(p, jnp.asarray(rc), jnp.asarray(theta), jnp.zeros(n_psi)))
    f = np.asarray(limb_profile_intensity(p, jnp.asarray(rc))) - p.ymin
    np.testing.assert_allclose(K.sum(axis=1), f, rtol=0, atol=1e-10 * f.max())
    psi = np.arctan2(-(rc[:, 0] - p.r0), rc[:, 1] - p.c0) % (2 * math.pi)
    step = 2 * math.pi / n_psi
    col = K[:, 2 * n_psi + 5]  # node (theta_2, psi_5)
    far = np.abs((psi - 5 * step + math.pi) % (2 * math.pi) - math.pi) > step
    assert np.all(col[far] == 0.0) and col.max() > 0.0


def test_albedo_prior_is_a_covariance_with_its_variance_on_the_diagonal():
    theta = np.arange(6) * math.radians(4.0)
    C = albedo_prior(theta, 30, 0.2, math.radians(12.0))
    assert C.shape == (180, 180)
    np.testing.assert_allclose(C, C.T, atol=1e-15)
    assert np.linalg.eigvalsh(C).min() > -1e-12
    np.testing.assert_allclose(np.diag(C), 0.04, rtol=2e-2)
    assert C[0, 1] < C[0, 0] and C[0, 15] < 0.01 * C[0, 0]  # node 1 is 12 deg along the limb; node 15 is 180 deg


def test_albedo_prior_factor_is_the_dense_prior_projected_on_the_psd_cone():
    """The block-circulant factor equals the eigendecomposition of the whole prior (its negative eigenvalues, which
    the squared exponential on the sphere has at long lengths, set to zero), for an odd and an even ring of nodes."""
    for n_psi, ell_deg in ((30, 12.0), (17, 40.0)):
        theta = np.arange(7) * math.radians(ell_deg / 2.0)
        th, ps = np.repeat(theta, n_psi), np.tile(np.arange(n_psi) * 2 * math.pi / n_psi, theta.size)
        cos_g = np.cos(th)[:, None] * np.cos(th) * np.cos(ps[:, None] - ps) + np.sin(th)[:, None] * np.sin(th)
        w, V = np.linalg.eigh(0.04 * np.exp(-0.5 * (np.arccos(np.clip(cos_g, -1, 1)) / math.radians(ell_deg)) ** 2))
        dense = (V * np.maximum(w, 0.0)) @ V.T
        F = albedo_prior_factor(theta, n_psi, 0.2, math.radians(ell_deg))
        np.testing.assert_allclose(F @ F.T, dense, rtol=0, atol=1e-9 * w.max())
        assert F.shape[1] <= th.size


def test_lunar_lambert_slope_is_the_weights_relative_derivative():
    """McEwen's ``d ln L / d alpha`` against central differences of ``ln L``; 0 where the weight is clipped."""
    from jaxlimb.models import lunar_lambert_slope, lunar_lambert_weight

    for deg in (0.5, 5.0, 30.0, 60.0, 90.0):
        a, h = math.radians(deg), 1e-6
        fd = (math.log(lunar_lambert_weight(a + h)) - math.log(lunar_lambert_weight(a - h))) / (2 * h)
        assert abs(lunar_lambert_slope(a) - fd) < 1e-6 * max(1.0, abs(fd))
    assert lunar_lambert_weight(math.radians(-5.0)) == 1.0 and lunar_lambert_slope(math.radians(-5.0)) == 0.0
    assert lunar_lambert_weight(math.radians(150.0)) == 0.0 and lunar_lambert_slope(math.radians(150.0)) == 0.0


def test_the_field_factor_formed_by_blocks_is_the_columns_times_the_prior_factor():
    """``albedo_field_factor`` never forms ``K``: by the prior's blocks (a Fourier vector in the position angle times an
    eigenvector in the surface angle) it is ``K F`` to rounding, for every correlation length the pipeline uses."""
    for a, ell_deg in ((60.0, 8.0), (60.0, 16.0), (23.0, 32.0), (200.0, 8.0)):
        p, rc = _limb(a=a)
        theta, n_psi = albedo_nodes(p, rc, math.radians(ell_deg))
        dense = albedo_field_columns(p, rc, theta, np.zeros(n_psi)) @ albedo_prior_factor(theta, n_psi, 0.3,
                                                                                          math.radians(ell_deg))
        U = albedo_field_factor(p, rc, 0.3, math.radians(ell_deg))
        np.testing.assert_allclose(U, dense, rtol=0, atol=1e-12 * np.abs(dense).max())


def test_surface_angle_nodes_are_padded_to_buckets_without_changing_a_column():
    """A limb's depth in nodes changes with every frame's radius; the program is compiled per bucket of nodes
    (2, 3, 4, 6, 8, 12, ...) and the padding's nodes are zero: the columns on ``m`` nodes are those of a program made
    for exactly ``m``, the last node holding the deepest angles."""
    assert [node_bucket(m) for m in (1, 2, 3, 4, 5, 7, 9, 13, 17, 25)] == [2, 2, 3, 4, 6, 8, 12, 16, 24, 32]
    p, rc = _limb(a=80.0)
    theta, n_psi = albedo_nodes(p, rc, math.radians(8.0))
    assert node_bucket(theta.size) > theta.size  # this limb is padded
    K = albedo_field_columns(p, rc, theta, np.zeros(n_psi)).reshape(rc.shape[0], theta.size, n_psi)
    f = np.asarray(limb_profile_intensity(p, jnp.asarray(rc))) - p.ymin
    np.testing.assert_allclose(K.sum(axis=(1, 2)), f, rtol=0, atol=1e-10 * f.max())  # no weight lost to the padding
    short = albedo_field_columns(p, rc, theta[:-1], np.zeros(n_psi)).reshape(rc.shape[0], theta.size - 1, n_psi)
    assert node_bucket(theta.size - 1) != node_bucket(theta.size)  # two programs
    np.testing.assert_allclose(short[:, :-1], K[:, :-2], rtol=0, atol=1e-12 * f.max())  # the same hats before the last
