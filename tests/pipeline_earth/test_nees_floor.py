"""benchmarks/nees_floor.py: the NEES of a results record under a floored centre covariance."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from nees_floor import floored_nees, table  # noqa: E402


def test_floored_nees_limits():
    C = np.array([[4e-6, 1e-6], [1e-6, 1e-4]])
    rec = {"status": "ok", "cov_rc": C.tolist(), "err_rc": [0.01, -0.02]}
    e = np.array(rec["err_rc"])
    assert np.isclose(floored_nees(rec, 0.0), e @ np.linalg.solve(C, e))
    assert np.isclose(floored_nees(rec, 1.0), e @ e)  # a floor above both eigenvalues: isotropic 1 px^2
    assert floored_nees(rec, 0.0075) < floored_nees(rec, 0.0)
    res = {"records": {"earth": {"own": [rec, {"status": "error"}]}}}
    assert table(res, "earth", [0.0, 1.0])["own"] == [floored_nees(rec, 0.0), floored_nees(rec, 1.0)]
