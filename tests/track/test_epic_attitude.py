"""benchmarks/track_epic.py: the quaternion's accuracy from the other frames (leave one out)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from track_epic import DATA, boresight_angle, leave_one_out_sigma  # noqa: E402


def test_leave_one_out_sigma_ignores_the_frame_itself():
    angles = np.array([1.0, 2.0, 2.0, 100.0])
    sig = leave_one_out_sigma(angles)
    assert np.isclose(sig[3], np.sqrt((1 + 4 + 4) / 3 / 2))  # the outlier does not size its own sigma
    assert np.all(sig[:3] > sig[3])  # ... but it widens the others'
    rng = np.random.default_rng(0)
    theta = np.hypot(*rng.normal(0.0, 3e-5, (2, 20000)))  # two axes of 30 microrad
    assert np.allclose(leave_one_out_sigma(theta), 3e-5, rtol=0.02)


@pytest.mark.skipif(not DATA.exists(), reason="the shared EPIC frames are not here")
def test_epic_quaternions_disagree_with_their_positions_beyond_their_rounding():
    stems = [p.with_suffix("").with_suffix("") for p in sorted(DATA.resolve().glob("*.metadata.json"))]
    angles = np.array([boresight_angle(s) for s in stems])
    assert len(angles) == 6
    assert np.all(angles > 2e-5)  # every frame: more than the five decimals' rounding step
    assert np.all(angles < 5e-4)  # the boresight is the Earth's direction to a fraction of a mrad
