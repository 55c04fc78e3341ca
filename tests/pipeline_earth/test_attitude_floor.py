"""benchmarks/earth_attitude_floor.py: the efficient estimator's pooled errors and the per-range summary."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from earth_attitude_floor import efficient_errors, summarise  # noqa: E402


def _row(range_km: float, floor: float, crlb, err: float, status: str = "ok") -> dict:
    unknown = {"status": status, "center_err_px": err, "crlb_rc": list(crlb)} if status == "ok" else {"status": status}
    return {"range_km": range_km, "floor_px": floor, "known": {"status": "ok", "center_err_px": 0.01}, "unknown": unknown}


def test_efficient_errors_are_the_floor_plus_the_bound():
    """A pure floor gives its value exactly; pure noise gives the Rayleigh median ``sigma sqrt(2 ln 2)``; a failed frame
    adds nothing."""
    rng = np.random.default_rng(0)
    e = efficient_errors([_row(4e4, 0.3, (0.0, 0.0), 0.3)], 100, rng)
    assert e.shape == (100,) and np.allclose(e, 0.3)
    e = efficient_errors([_row(4e5, 0.0, (0.1, 0.1), 0.1), _row(4e5, 0.0, (0.1, 0.1), 0.1, "error")], 20000, rng)
    assert e.shape == (20000,) and abs(np.median(e) - 0.1 * np.sqrt(2 * np.log(2))) < 0.003


def test_summary_splits_near_and_far():
    rows = [_row(4e4, 0.3, (0.01, 0.01), 0.31), _row(4e5, 0.005, (0.1, 0.05), 0.12),
            _row(4e5, 0.005, (0.1, 0.05), 0.0, "error")]
    s = summarise(rows, 2000, 1)
    assert s["near"]["answered_unknown"] == 1 and s["far"]["answered_unknown"] == 1 and s["all"]["frames"] == 3
    assert s["near"]["locate_unknown"]["median_px"] == 0.31 and s["far"]["floor_median_px"] == 0.005
    assert s["near"]["share_bound_above_target"] == 1.0 and s["far"]["share_bound_above_target"] == 0.0
    assert abs(s["near"]["efficient_unknown"]["median_px"] - 0.3) < 0.01
