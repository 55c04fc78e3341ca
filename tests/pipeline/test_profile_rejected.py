"""A physical profile rejected for its ``L`` band leaves the sigmoid to answer, with the move between them in its
covariance (``jaxlimb.pipeline.sphere.refit.sphere_refit``)."""

from __future__ import annotations

import numpy as np

from jaxlimb.analysis.montecarlo import trial_seed
from jaxlimb.analysis.pipeline_study import FamilyTrial
from jaxlimb.geometry.hints import Hints
from jaxlimb.models.lunar_lambert import PHYSICAL_L
from jaxlimb.pipeline import locate
from jaxlimb.pipeline.profile import passes
from jaxlimb.pipeline.profile.passes import in_band
from jaxlimb.pipeline.sphere import refit
from jaxlimb.render.independent.families import MOON_FAMILIES
from jaxlimb.pipeline import covariance_block


def _nees(case, m) -> float:
    e = np.array(m.center_rc) - np.array(case.truth.body_center_rc)
    c = m.covariance
    P = covariance_block(c)
    return float(e @ np.linalg.solve(P, e))


def test_rejected_profile_move_is_carried_by_the_sigmoid(monkeypatch):
    """Trial 335 of ``jaxlimb montecarlo --pipeline --families all --n 420 --seed 1`` (``spots``, phase 111 deg), its
    ``L`` band held to the physical range (the albedo term's sigma of ``L`` now widens the band enough for this
    profile to answer): the profile is rejected, and the sphere-shaped sigmoid that answers is about a pixel off,
    along the Sun, at a noise sigma of 0.04 px.  With the move to the rejected profile as its sigma the NEES is below
    the chi-square 99.9 % point; the estimate is the same.  (The albedo field is held off: under it this profile's
    ``L`` comes back inside the band, and the profile answers.)"""
    monkeypatch.setattr(passes, "l_band", lambda fit: PHYSICAL_L)
    monkeypatch.setattr(refit, "with_albedo_field", lambda frame, res: res)
    case = FamilyTrial(families=tuple(MOON_FAMILIES)).case(trial_seed(1, 335), 335)
    m = locate(case.image, case.camera, Hints.from_dict(case.hints))
    assert "L" in m.extras["profile_rejected"]
    assert _nees(case, m) < 13.8
    original = refit.lunar_profile_refit
    monkeypatch.setattr(refit, "lunar_profile_refit", lambda *a: (original(*a)[0], None))
    m0 = locate(case.image, case.camera, Hints.from_dict(case.hints))
    assert np.allclose(m0.center_rc, m.center_rc, atol=1e-9)
    assert _nees(case, m0) > 100.0


def test_band_asked_under_the_field(monkeypatch):
    """The same frame with the field on: the one-albedo ``L`` is outside the held band, the refit's (-0.095) inside
    it, so the refit under the field answers (0.175 px off, where the sigmoid is about a pixel off)."""
    monkeypatch.setattr(passes, "l_band", lambda fit: PHYSICAL_L)
    case = FamilyTrial(families=tuple(MOON_FAMILIES)).case(trial_seed(1, 335), 335)
    m = locate(case.image, case.camera, Hints.from_dict(case.hints))
    assert "profile_rejected" not in m.extras and PHYSICAL_L[0] <= m.extras["profile"]["L"] <= PHYSICAL_L[1]
    assert np.hypot(*np.subtract(m.center_rc, case.truth.body_center_rc)) < 0.25


def test_in_band_holds_the_refit_to_the_physical_range():
    """The one-albedo ``L`` is tested against its band, the refit's against the physical range itself."""
    band = (-0.8, 1.8)
    assert in_band((1.5, 3.0), band)  # inside the band as fitted: the refit answers whatever its L
    assert in_band((-0.9, 0.02), band)  # a spotted limb: below the band, physical under the field
    assert not in_band((2.0, 1.5), band)  # a flat disc: inside the band under the field, but no surface's L
    assert not in_band((2.0, 2.0), band)
