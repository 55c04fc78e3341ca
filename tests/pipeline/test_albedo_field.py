"""The profile with the albedo as a marginalised Gaussian field (:mod:`jaxlimb.pipeline.profile.albedo_field`)."""

import math

import jax
import numpy as np
import pytest

from jaxlimb.imaging import Hints
from jaxlimb.models import LimbProfileParams
from jaxlimb.pipeline import LocateOptions, locate
from jaxlimb.pipeline.profile.albedo_field import field_basis
from jaxlimb.pipeline.profile.albedo_prior import field_likelihood
from jaxlimb.render.independent import MOON_FAMILIES, moon_case
from jaxlimb.pipeline import covariance_block

from ._scenes import SMALL_CAMERA, errors, scene, sun_hints

jax.config.update("jax_enable_x64", True)


def test_albedo_field_profile_keeps_a_uniform_moons_answer():
    """On a uniform-albedo Moon the field's amplitude comes out near 0: the centre is the one-albedo profile's to
    0.02 px, and the covariance still covers the truth."""
    img, tr = scene(30000.0, 45.0, (200.0, 250.0), 30.0, seed=2)
    one = locate(img, SMALL_CAMERA, sun_hints(tr))
    field = locate(img, SMALL_CAMERA, sun_hints(tr), LocateOptions(profile="albedo-field"))
    assert math.dist(one.center_rc, field.center_rc) < 0.02
    e = np.subtract(field.center_rc, tr.center_rc)
    c = field.covariance
    P = covariance_block(c)
    assert errors(field, tr)[0] < 0.05 and float(e @ np.linalg.solve(P, e)) < 13.8


@pytest.mark.parametrize("family, idx, widened", [("spots", 0, False), ("minnaert", 2, True)])
def test_albedo_field_takes_the_profile_that_explains_the_limb_with_the_field(family, idx, widened):
    """An albedo of smooth spots reads as limb brightening to a one-albedo fit (the default is 0.19 px off on this
    frame); with the field the unwidened profile explains the pixels better, and the centre is within 0.05 px.  A
    true Minnaert rim keeps the brightening exponent.  Both covariances cover the error."""
    case = moon_case(family, np.random.default_rng([2026, 0, MOON_FAMILIES.index(family), idx]))
    m = locate(case.image, case.camera, Hints.from_dict(case.hints), LocateOptions(profile="albedo-field"))
    e = np.array(m.center_rc) - np.array(case.truth.body_center_rc)
    c = m.covariance
    P = covariance_block(c)
    assert float(np.hypot(*e)) < 0.05 and float(e @ np.linalg.solve(P, e)) < 13.8
    assert (m.extras["profile"]["kappa"] > 0.1) == widened


def test_restricted_likelihood_takes_the_fits_share_of_the_field_out():
    """Residuals of a least-squares fit (centre, radius, amplitude, sky) to pixels under a field of amplitude 0.1 and
    noise: the field's basis as the residuals see it gives the amplitude back (median of 5 draws within 30 %); the
    field's own basis reads what the fit absorbed as more field (median at least twice the truth)."""
    from jaxlimb.models.lunar_lambert import profile_model
    from jaxlimb.pipeline.profile.albedo_field import restricted

    p = LimbProfileParams(r0=300.0, c0=310.0, a=60.0, theta=0.0, rho=1.0, sigma=0.9, amp=1000.0, ymin=5.0, sun_r=0.0,
                          sun_c=1.0, phase=0.3, inv_f=1e-4, L=0.5, L_slope=-1.0, L_ref=0.6)
    rng = np.random.default_rng(5)
    ang, d = rng.uniform(-0.5 * math.pi, 0.5 * math.pi, 3000), 60.0 + rng.uniform(-6.0, 6.0, 3000)
    rc = np.column_stack([300.0 + d * np.sin(ang), 310.0 + d * np.cos(ang)])
    _, cols = profile_model(p).intensity_and_jacobian_columns(p, jax.numpy.asarray(rc))
    names = profile_model(p).param_names
    J = np.stack([np.asarray(cols[names.index(k)]) for k in ("r0", "c0", "a", "amp", "ymin")], axis=1)
    Q, S = field_basis(p, rc, math.radians(16.0))
    fit_out = np.eye(len(rc)) - J @ np.linalg.pinv(J)
    taus = []
    for _ in range(5):
        r = fit_out @ (Q @ (0.1 * S * rng.normal(size=S.size)) + 5.0 * rng.normal(size=len(rc)))
        taus.append([math.sqrt(field_likelihood(r, *b)[1]) for b in (restricted((Q, S), J), (Q, S))])
    own, raw = np.median(taus, axis=0)
    assert 0.07 < own < 0.13 and raw > 0.2, taus
