"""``locate``'s physical profile refitted under the albedo field its residuals ask for
(:func:`jaxlimb.pipeline.profile.albedo_field.with_albedo_field`)."""

import math

import jax
import numpy as np

from jaxlimb.imaging import Hints
from jaxlimb.pipeline import covariance_block, locate
from jaxlimb.pipeline.sphere import refit as sphere_refit
from jaxlimb.render.independent import MOON_FAMILIES, moon_case

from ._scenes import SMALL_CAMERA, scene, sun_hints

jax.config.update("jax_enable_x64", True)


def _error_and_nees(m, truth_rc):
    e = np.array(m.center_rc) - np.array(truth_rc)
    return float(np.hypot(*e)), float(e @ np.linalg.solve(covariance_block(m.covariance), e))


def test_spots_no_longer_move_the_centre(monkeypatch):
    """Frame 4 of the independent renderer's ``spots`` family (overlapping albedo spots 9-26 deg across, 15-35 %
    deep, all over the Moon): the least-squares profile follows the spots 0.33 px off; refitted under the field its
    residuals ask for, within 0.08 px (0.038 measured), the covariance covering the error."""
    case = moon_case("spots", np.random.default_rng([2026, 0, MOON_FAMILIES.index("spots"), 4]))
    m = locate(case.image, case.camera, Hints.from_dict(case.hints))
    err, nees = _error_and_nees(m, case.truth.body_center_rc)
    assert err < 0.08 and nees < 13.8
    monkeypatch.setattr(sphere_refit, "with_albedo_field", lambda frame, answer: answer)
    assert _error_and_nees(locate(case.image, case.camera, Hints.from_dict(case.hints)),
                           case.truth.body_center_rc)[0] > 0.25


def test_a_uniform_albedo_keeps_the_least_squares_answer(monkeypatch):
    """On a uniform-albedo Moon the field's amplitude comes out near 0: the centre is the least-squares profile's to
    0.005 px and its sigma within 25 % of it."""
    img, tr = scene(30000.0, 45.0, (200.0, 250.0), 30.0, seed=2)
    m = locate(img, SMALL_CAMERA, sun_hints(tr))
    monkeypatch.setattr(sphere_refit, "with_albedo_field", lambda frame, answer: answer)
    ls = locate(img, SMALL_CAMERA, sun_hints(tr))
    assert math.dist(m.center_rc, ls.center_rc) < 0.005
    s, s_ls = (math.sqrt(np.trace(covariance_block(x.covariance))) for x in (m, ls))
    assert abs(s / s_ls - 1.0) < 0.25


def _earth_spots(seed: int):
    from jaxlimb.render.independent.families import albedo_case

    return albedo_case("earth", 40_000.0, 35.0, "spots", seed, 0)


def test_earth_spots_no_longer_move_the_centre(monkeypatch):
    """The Earth (WGS-84, Lambert, attitude known) at 40 000 km under albedo spots all over it: the least-squares
    profile reads the spots as a smear and follows them 0.2 px off; the ellipsoid's profile refitted under the field,
    its shape held, is within 0.05 px (0.008 measured), the covariance covering the error, and the field drops the
    smear (:func:`~jaxlimb.pipeline.profile.albedo_field.field_preferred`)."""
    from jaxlimb.pipeline.ellipsoid import profile as ellipsoid_profile

    case = _earth_spots(2)
    m = locate(case.image, case.camera, Hints.from_dict(case.hints))
    err, nees = _error_and_nees(m, case.truth.body_center_rc)
    assert err < 0.05 and nees < 13.8 and "blur_aniso" not in m.extras["profile"]
    monkeypatch.setattr(ellipsoid_profile, "with_albedo_field", lambda frame, answer, shape: answer)
    monkeypatch.setattr(ellipsoid_profile, "field_preferred", lambda fits: fits[-1])
    assert _error_and_nees(locate(case.image, case.camera, Hints.from_dict(case.hints)),
                           case.truth.body_center_rc)[0] > 0.15


def test_field_keeps_a_true_smear():
    """The field's evidence (:func:`~jaxlimb.pipeline.profile.albedo_field.field_preferred`) keeps the anisotropic
    blur on a motion-smeared Earth (it answers within 0.02 px), where it drops it on the spotted Earth above."""
    from jaxlimb.render.independent.families import EARTH_FAMILIES, earth_case

    case = earth_case("motion", np.random.default_rng([2026, 1, EARTH_FAMILIES.index("motion"), 1]), far=True)
    m = locate(case.image, case.camera, Hints.from_dict(case.hints))
    assert _error_and_nees(m, case.truth.body_center_rc)[0] < 0.02 and "blur_aniso" in m.extras["profile"]
