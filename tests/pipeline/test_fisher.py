"""The fit's Fisher matrix (:func:`jaxlimb.pipeline.sigmoid.fisher_information`, every ``locate``'s CRLB) is formed from
the model's analytic Jacobian columns: it is the autodiff Jacobian's ``J^T diag(w^2) J / sigma^2``."""

import jax
import numpy as np
import pytest

from jaxlimb.models import CIRCLE, ELLIPSE_RAMP, LIMB_PROFILE
from jaxlimb.models.gradcheck import _random_case
from jaxlimb.pipeline.sigmoid import fisher_information
from jaxlimb.pipeline.stages import FitData

jax.config.update("jax_enable_x64", True)


@pytest.mark.parametrize("model", [CIRCLE, ELLIPSE_RAMP, LIMB_PROFILE], ids=lambda m: m.name)
def test_fisher_matrix_is_the_autodiff_jacobians_with_weights_and_fixed_parameters(model):
    rng = np.random.default_rng(7)
    p, coords = _random_case(model, rng, 500)[:2]
    coords = np.asarray(coords, float)
    w = rng.uniform(0.5, 1.5, coords.shape[0])
    fixed = model.param_names[-2:]
    F = fisher_information(model, p, FitData(coords, np.zeros(coords.shape[0]), w, 0.0, 1.0), fixed, 2.0)
    J = np.asarray(jax.jacfwd(lambda v: model.intensity(model.params_type.from_vector(v), coords))(p.to_vector()))
    J = J[:, list(model.free_indices(fixed))]
    want = J.T @ (J * (w * w)[:, None]) / 4.0
    assert F.shape == (len(model.param_names) - 2,) * 2
    np.testing.assert_allclose(F, want, rtol=0, atol=1e-12 * np.abs(want).max())
