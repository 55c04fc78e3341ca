"""An unknown albedo field's consider term on a ``locate`` answer (:mod:`jaxlimb.analysis.albedo_consider`)."""

import jax
import numpy as np

from jaxlimb.analysis.albedo_consider import albedo_consider_of
from jaxlimb.analysis.located import located_fit
from jaxlimb.render.independent import MOON_FAMILIES, moon_case

jax.config.update("jax_enable_x64", True)


def test_locates_covariance_covers_a_spots_moon_through_the_albedo_term():
    """A Moon under an albedo of smooth spots (the independent renderer's ``spots`` family): ``locate`` is 0.33 px off,
    a move of the edge the residuals do not show (without the albedo term its NEES was 33); the albedo field's term,
    of amplitude near the spots' depth, covers it alone, and ``locate``'s covariance with it."""
    case = moon_case("spots", np.random.default_rng([2026, 0, MOON_FAMILIES.index("spots"), 2]))
    lf = located_fit(case.image, case.camera, case.hints)
    ac = albedo_consider_of(lf)
    e = np.array(lf.measurement.center_rc) - np.array(case.truth.body_center_rc)
    assert 0.2 < float(np.hypot(*e)) < 0.5 and 0.05 < ac.tau < 0.35
    assert float(e @ np.linalg.solve(ac.center, e)) < 9.21 and float(e @ np.linalg.solve(ac.locate, e)) < 9.21
