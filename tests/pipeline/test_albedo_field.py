"""The profile with the albedo as a marginalised Gaussian field (:mod:`jaxlimb.pipeline.profile.albedo_field`)."""

import math

import jax
import numpy as np
import pytest

from jaxlimb.imaging import Hints
from jaxlimb.models import LimbProfileParams
from jaxlimb.pipeline import LocateOptions, locate
from jaxlimb.pipeline.profile.albedo_field import field_basis, field_likelihood
from jaxlimb.render.independent import MOON_FAMILIES, moon_case

from ._scenes import SMALL_CAMERA, errors, scene, sun_hints

jax.config.update("jax_enable_x64", True)


def test_marginal_likelihood_recovers_the_noise_and_the_fields_amplitude():
    """Residuals drawn as ``U a + e`` (``a`` from the field's prior of amplitude 0.15, ``e`` noise of 30 DN) give back
    both; residuals of noise alone give an amplitude that leaves no albedo variance to speak of."""
    p = LimbProfileParams(r0=300.0, c0=310.0, a=60.0, theta=0.0, rho=1.0, sigma=0.9, amp=1000.0, ymin=5.0, sun_r=0.6,
                          sun_c=0.8, phase=0.8, inv_f=1e-4, L=0.5)
    rng = np.random.default_rng(3)
    ang, d = rng.uniform(0.0, 2 * math.pi, 2500), 60.0 + rng.uniform(-6.0, 6.0, 2500)
    rc = np.column_stack([300.0 + d * np.sin(ang), 310.0 + d * np.cos(ang)])
    Q, S = field_basis(p, rc, math.radians(16.0))
    noise = 30.0 * rng.normal(size=len(rc))
    s2, t2, _ = field_likelihood(Q @ (0.15 * S * rng.normal(size=S.size)) + noise, Q, S)
    assert abs(math.sqrt(s2) / 30.0 - 1.0) < 0.05 and 0.09 < math.sqrt(t2) < 0.25, (s2, t2)
    s2, t2, _ = field_likelihood(noise, Q, S)
    assert abs(math.sqrt(s2) / 30.0 - 1.0) < 0.05 and math.sqrt(t2) * S.max() < 0.5 * math.sqrt(s2), (s2, t2)


def test_albedo_field_profile_keeps_a_uniform_moons_answer():
    """On a uniform-albedo Moon the field's amplitude comes out near 0: the centre is the one-albedo profile's to
    0.02 px, and the covariance still covers the truth."""
    img, tr = scene(30000.0, 45.0, (200.0, 250.0), 30.0, seed=2)
    one = locate(img, SMALL_CAMERA, sun_hints(tr))
    field = locate(img, SMALL_CAMERA, sun_hints(tr), LocateOptions(profile="albedo-field"))
    assert math.dist(one.center_rc, field.center_rc) < 0.02
    e = np.subtract(field.center_rc, tr.center_rc)
    c = field.covariance
    P = np.array([[c["center_r"]["center_r"], c["center_r"]["center_c"]], [c["center_c"]["center_r"], c["center_c"]["center_c"]]])
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
    P = np.array([[c["center_r"]["center_r"], c["center_r"]["center_c"]], [c["center_c"]["center_r"], c["center_c"]["center_c"]]])
    assert float(np.hypot(*e)) < 0.05 and float(e @ np.linalg.solve(P, e)) < 13.8
    assert (m.extras["profile"]["kappa"] > 0.1) == widened
