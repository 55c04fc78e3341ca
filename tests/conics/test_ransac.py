"""RANSAC for circles with the pyramid index rotation (Aerospace 2015 §4.3)."""

from __future__ import annotations

import math
from itertools import combinations

import numpy as np
import pytest

from jaxlimb.conics import RansacOptions, pyramid_triplets, ransac_circle
from jaxlimb.errors import ConfigError, TooManyOutliersError


def _data(rng, n_in, n_out, center=(100.0, 50.0), r=80.0, span=3.0, noise=0.5):
    t = rng.uniform(0, span, n_in)
    p = np.c_[center[0] + r * np.sin(t), center[1] + r * np.cos(t)] + rng.normal(0, noise, (n_in, 2))
    out = rng.uniform(-50, 250, (n_out, 2))
    # keep real outliers only (farther than 5 px from the circle)
    out = out[np.abs(np.hypot(out[:, 0] - center[0], out[:, 1] - center[1]) - r) > 5]
    P = np.r_[p, out]
    is_in = np.r_[np.ones(n_in, bool), np.zeros(out.shape[0], bool)]
    perm = rng.permutation(P.shape[0])
    return P[perm], is_in[perm]


@pytest.mark.parametrize("frac_out", [0.3, 0.45, 0.6])
def test_ransac_rejects_outliers(rng, frac_out):
    n = 400
    n_out = int(frac_out * n)
    P, is_in = _data(rng, n - n_out, n_out)
    assert (~is_in).mean() >= frac_out - 0.05
    res = ransac_circle(P, RansacOptions(threshold=2.0, max_tests=500))
    assert res
    assert res.circle is not None
    assert math.hypot(res.circle.center_rc[0] - 100, res.circle.center_rc[1] - 50) < 0.2
    assert abs(res.circle.radius - 80.0) < 0.2
    # every true outlier rejected, at least 98 % of inliers kept
    assert not np.any(res.inliers & ~is_in)
    assert (res.inliers & is_in).sum() >= 0.98 * is_in.sum()


def test_ransac_is_deterministic(rng):
    P, _ = _data(rng, 200, 100)
    a = ransac_circle(P, RansacOptions(threshold=2.0, max_tests=200))
    b = ransac_circle(P, RansacOptions(threshold=2.0, max_tests=200))
    assert a.circle == b.circle and np.array_equal(a.inliers, b.inliers)


def test_ransac_failure_is_falsy_or_raises(rng):
    P = rng.uniform(0, 500, (300, 2))
    res = ransac_circle(P, RansacOptions(threshold=1.0, max_tests=300, min_inliers=30))
    assert not res and res.circle is None and res.n_inliers == 0 and res.reason
    with pytest.raises(TooManyOutliersError):
        ransac_circle(P, RansacOptions(threshold=1.0, max_tests=300, min_inliers=30), raise_on_failure=True)


def test_ransac_radius_range_excludes_model(rng):
    P, _ = _data(rng, 200, 50)
    res = ransac_circle(P, RansacOptions(threshold=2.0, radius_range=(10.0, 40.0)))
    assert not res
    res = ransac_circle(P, RansacOptions(threshold=2.0, radius_range=(60.0, 100.0)))
    assert res and abs(res.circle.radius - 80) < 0.3


def test_pyramid_order_unique_complete():
    n = 9
    t = pyramid_triplets(n, 10_000)
    assert t.shape == (math.comb(n, 3), 3)
    assert {tuple(x) for x in t} == set(combinations(range(n), 3))
    assert np.all(t[:, 0] < t[:, 1]) and np.all(t[:, 1] < t[:, 2])
    # the paper's order: dj outermost, dk middle, i innermost
    dj, dk = t[:, 1] - t[:, 0], t[:, 2] - t[:, 1]
    key = dj * 100 + dk
    assert np.all(np.diff(key) >= 0)
    assert t[:3].tolist() == [[0, 1, 2], [1, 2, 3], [2, 3, 4]]
    assert pyramid_triplets(n, 5).shape == (5, 3)
    assert pyramid_triplets(2, 5).shape == (0, 3)


@pytest.mark.parametrize(
    "kw",
    [
        {"threshold": 0.0},
        {"threshold": float("nan")},
        {"max_tests": 0},
        {"min_inliers": 2},
        {"min_inlier_fraction": 1.5},
        {"radius_range": (5.0, 1.0)},
        {"refine_iterations": -1},
    ],
)
def test_ransac_options_validation(kw):
    with pytest.raises(ConfigError):
        RansacOptions(**kw)
