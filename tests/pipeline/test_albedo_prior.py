"""The albedo as an unknown Gaussian field: its amplitude by marginal likelihood and its consider covariance
(:mod:`jaxlimb.pipeline.profile.albedo_prior`)."""

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxlimb.models import LimbProfileParams
from jaxlimb.models.lunar_lambert import profile_model
from jaxlimb.models.profile_columns import albedo_field_factor
from jaxlimb.pipeline.profile.albedo_field import field_basis
from jaxlimb.pipeline.profile.albedo_prior import albedo_consider, along_limb, field_likelihood

jax.config.update("jax_enable_x64", True)

P = LimbProfileParams(r0=300.0, c0=310.0, a=60.0, theta=0.0, rho=1.0, sigma=0.9, amp=1000.0, ymin=5.0, sun_r=0.0,
                      sun_c=1.0, phase=0.3, inv_f=1e-4, L=0.5, L_slope=-1.0, L_ref=0.6)


def _ring(rng, n=3000):
    ang, d = rng.uniform(-0.5 * math.pi, 0.5 * math.pi, n), 60.0 + rng.uniform(-6.0, 6.0, n)  # the lit half
    return np.column_stack([300.0 + d * np.sin(ang), 310.0 + d * np.cos(ang)])


def test_marginal_likelihood_recovers_the_noise_and_the_fields_amplitude():
    """Residuals drawn as ``U a + e`` (``a`` from the field's prior of amplitude 0.15, ``e`` noise of 30 DN) give back
    both; residuals of noise alone give an amplitude that leaves no albedo variance to speak of."""
    p = LimbProfileParams(r0=300.0, c0=310.0, a=60.0, theta=0.0, rho=1.0, sigma=0.9, amp=1000.0, ymin=5.0, sun_r=0.6,
                          sun_c=0.8, phase=0.8, inv_f=1e-4, L=0.5, L_slope=-1.0, L_ref=0.6)
    rng = np.random.default_rng(3)
    ang, d = rng.uniform(0.0, 2 * math.pi, 2500), 60.0 + rng.uniform(-6.0, 6.0, 2500)
    rc = np.column_stack([300.0 + d * np.sin(ang), 310.0 + d * np.cos(ang)])
    Q, S = field_basis(p, rc, math.radians(16.0))
    noise = 30.0 * rng.normal(size=len(rc))
    s2, t2, _ = field_likelihood(Q @ (0.15 * S * rng.normal(size=S.size)) + noise, Q, S)
    assert abs(math.sqrt(s2) / 30.0 - 1.0) < 0.05 and 0.09 < math.sqrt(t2) < 0.25, (s2, t2)
    s2, t2, _ = field_likelihood(noise, Q, S)
    assert abs(math.sqrt(s2) / 30.0 - 1.0) < 0.05 and math.sqrt(t2) * S.max() < 0.5 * math.sqrt(s2), (s2, t2)


def test_along_limb_keeps_what_varies_along_the_limb_only():
    """A function of the distance to the limb times a quadratic in the position angle is removed to rounding; a
    pattern of 10 deg along the limb keeps most of its power."""
    rc = _ring(np.random.default_rng(0))
    s = np.hypot(rc[:, 0] - 300.0, rc[:, 1] - 310.0) - 60.0
    psi = np.arctan2(rc[:, 0] - 300.0, rc[:, 1] - 310.0)
    smooth = np.exp(-0.5 * np.floor(s) ** 2) * (1.0 + 0.3 * psi - 0.2 * psi ** 2)
    assert np.max(np.abs(along_limb(smooth, s, psi))) < 1e-10
    wiggle = np.cos(psi * 36.0) * np.exp(-0.5 * np.floor(s) ** 2)
    assert np.sum(along_limb(wiggle, s, psi) ** 2) > 0.9 * np.sum(wiggle ** 2)


def test_consider_covariance_is_the_scatter_a_field_gives_the_least_squares_centre():
    """Pixels of a profile under albedo fields drawn from the prior (amplitude 0.1, 16 deg) and noise: the centre of
    the least-squares fit scatters over 300 draws as the consider covariance estimated from one draw's residuals says
    (median over 12 draws, within a factor 1.6 in variance).  With no field, at least half of the draws give no term
    (the amplitude's maximum likelihood on its boundary): the median is below a tenth of the noise's."""
    rng = np.random.default_rng(5)
    rc = _ring(rng)
    f, cols = profile_model(P).intensity_and_jacobian_columns(P, jnp.asarray(rc))
    names = profile_model(P).param_names
    J = np.stack([np.asarray(cols[names.index(k)]) for k in ("r0", "c0", "a", "amp", "ymin")], axis=1)
    U = albedo_field_factor(P, rc, 1.0, math.radians(16.0))
    G = np.linalg.pinv(J)
    s = np.hypot(rc[:, 0] - 300.0, rc[:, 1] - 310.0) - 60.0
    draws = [0.1 * U @ rng.normal(size=U.shape[1]) + 5.0 * rng.normal(size=len(rc)) for _ in range(300)]
    x = np.array([G @ y for y in draws])
    noise = 25.0 * (G @ G.T)
    emp = np.cov(x[:, :2].T) - noise[:2, :2]
    est = np.median([albedo_consider(P, rc, J, y - J @ (G @ y), np.ones(len(rc)), s)[0][:2, :2].trace()
                     for y in draws[:12]])
    assert 1 / 1.6 < est / np.trace(emp) < 1.6, (est, np.trace(emp))
    null = [albedo_consider(P, rc, J, y - J @ (G @ y), np.ones(len(rc)), s)[0][:2, :2].trace()
            for y in 5.0 * rng.normal(size=(8, len(rc)))]
    assert np.median(null) < 0.1 * noise[:2, :2].trace(), null


def _nll(r, Q, S, s2, t2):
    y2, lam = (Q.T @ r) ** 2, s2 + t2 * S * S
    return 0.5 * ((r @ r - y2.sum()) / s2 + np.sum(y2 / lam) + (r.size - S.size) * math.log(s2) + np.sum(np.log(lam)))


def test_marginal_likelihood_is_the_two_dimensional_minimum():
    """The search over the ratio of the two variances (the noise's profiled out) lands on the minimum of the
    likelihood in both: no step of 1 % in either variance lowers it, inside the amplitude's bound or on it."""
    rng = np.random.default_rng(11)
    Q = np.linalg.qr(rng.normal(size=(1500, 40)))[0]
    S = np.exp(rng.uniform(0.0, 6.0, 40))
    for tau in (0.003, 0.05, 0.2, 2.0):
        r = Q @ (tau * S * rng.normal(size=40)) + 7.0 * rng.normal(size=1500)
        s2, t2, nll = field_likelihood(r, Q, S)
        assert abs(nll - _nll(r, Q, S, s2, t2)) < 1e-9 * abs(nll)
        for ds, dt in ((1.01, 1.0), (0.99, 1.0), (1.0, 1.01), (1.0, 0.99)):
            if t2 * dt <= 0.25:
                assert _nll(r, Q, S, s2 * ds, t2 * dt) >= nll - 1e-9 * abs(nll), (tau, ds, dt)
