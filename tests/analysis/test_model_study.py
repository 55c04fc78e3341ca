"""Model-only Monte Carlo: RMS vs Cramér-Rao bound on model-consistent data."""

import numpy as np
import pytest

from jaxlimb.analysis.crlb import crlb
from jaxlimb.analysis.model_study import ModelStudyOptions, model_problem, run_model_study
from jaxlimb.errors import LimbInputError
from jaxlimb.fitting import PaperGaussNewton


def test_rms_matches_crlb_and_bias_is_small():
    res = run_model_study(ModelStudyOptions(n=300, seed=11, radius=60.0, shape=(160, 160)))
    assert res["converged"] == 300
    for name, ratio in res["rms_over_crlb"].items():
        assert 0.8 <= ratio <= 1.2, (name, ratio)  # 300 samples: RMS known to ~4 %
        assert abs(res["bias"][name]) <= 0.25 * res["crlb"][name], name  # 5 sigma of the mean


def test_fixed_parameters_and_nonbatched_solver_path():
    opt = ModelStudyOptions(n=4, radius=40.0, shape=(120, 120), fixed=("k", "ymax", "ymin"))
    res = run_model_study(opt, PaperGaussNewton())
    assert set(res["rms"]) == {"r0", "c0", "radius"}
    assert res["converged"] == 4


def test_crlb_scales_with_sigma_and_pixels():
    model, truth, _, coords, _ = model_problem(ModelStudyOptions(radius=60.0, shape=(160, 160)))
    a = crlb(model, coords, truth, 10.0).std["r0"]
    b = crlb(model, coords, truth, 5.0).std["r0"]
    c = crlb(model, coords[::2], truth, 10.0).std["r0"]
    assert b == pytest.approx(a / 2, rel=1e-12)
    assert c == pytest.approx(a * np.sqrt(2), rel=0.05)
    with pytest.raises(LimbInputError, match="sigma"):
        crlb(model, coords, truth, 0.0)


@pytest.mark.parametrize("kw, match", [({"radius": -1.0}, "radius"), ({"n": 1}, "`n`"), ({"model": "square"}, "model")])
def test_bad_options(kw, match):
    with pytest.raises(LimbInputError, match=match):
        ModelStudyOptions(**kw)
