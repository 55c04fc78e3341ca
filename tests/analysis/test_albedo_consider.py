"""An unknown albedo field's consider covariance of a profile fit (:mod:`jaxlimb.analysis.albedo_consider`)."""

import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxlimb.models import LimbProfileParams
from jaxlimb.models.lunar_lambert import profile_model
from jaxlimb.analysis.albedo_consider import albedo_consider, albedo_consider_of, along_limb
from jaxlimb.analysis.located import located_fit
from jaxlimb.models.profile_columns import albedo_field_factor
from jaxlimb.render.independent import MOON_FAMILIES, moon_case

jax.config.update("jax_enable_x64", True)

P = LimbProfileParams(r0=300.0, c0=310.0, a=60.0, theta=0.0, rho=1.0, sigma=0.9, amp=1000.0, ymin=5.0, sun_r=0.0,
                      sun_c=1.0, phase=0.3, inv_f=1e-4, L=0.5, L_slope=-1.0, L_ref=0.6)


def _ring(rng, n=3000):
    ang, d = rng.uniform(-0.5 * math.pi, 0.5 * math.pi, n), 60.0 + rng.uniform(-6.0, 6.0, n)  # the lit half
    return np.column_stack([300.0 + d * np.sin(ang), 310.0 + d * np.cos(ang)])


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


def test_the_term_covers_a_spots_moon_that_locates_covariance_does_not():
    """A Moon under an albedo of smooth spots (the independent renderer's ``spots`` family): ``locate`` is 0.33 px off
    with a NEES of 33 (its model-error terms see the residuals, and the albedo's move of the edge leaves none); the
    albedo field's term, of amplitude near the spots' depth, covers it."""
    case = moon_case("spots", np.random.default_rng([2026, 0, MOON_FAMILIES.index("spots"), 2]))
    lf = located_fit(case.image, case.camera, case.hints)
    ac = albedo_consider_of(lf)
    e = np.array(lf.measurement.center_rc) - np.array(case.truth.body_center_rc)
    assert 0.2 < float(np.hypot(*e)) < 0.5 and 0.05 < ac.tau < 0.35
    assert float(e @ np.linalg.solve(ac.locate, e)) > 13.8 > 9.21 > float(e @ np.linalg.solve(ac.widened, e))
