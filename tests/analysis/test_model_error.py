"""The cluster-robust model-error term (jaxlimb.analysis.model_error)."""

import numpy as np

from jaxlimb.analysis.model_error import cluster_robust_covariance, sector_groups, with_model_error


def _line_fit(r_extra, seed=0, n=4000, G=40):
    rng = np.random.default_rng(seed)
    x = np.linspace(-1, 1, n)
    J = np.column_stack([np.ones(n), x])
    y = 0.1 * rng.standard_normal(n) + r_extra(x)
    beta = np.linalg.lstsq(J, y, rcond=None)[0]
    r = y - J @ beta
    C = np.sum(r**2) / (n - 2) * np.linalg.inv(J.T @ J)
    return C, cluster_robust_covariance(J, r, np.minimum((np.arange(n) * G) // n, G - 1))


def test_exact_model_gives_the_noise_covariance_on_average():
    ratios = [np.diag(Cs) / np.diag(C) for C, Cs in (_line_fit(lambda x: 0 * x, s) for s in range(30))]
    assert np.allclose(np.mean(ratios, axis=0), 1.0, atol=0.15)


def test_correlated_misfit_widens_it_and_the_floor_holds():
    C, Cs = _line_fit(lambda x: 0.05 * np.sin(6 * x))  # a smooth model error the line cannot follow
    assert np.all(np.diag(Cs) > 3 * np.diag(C))
    Cn = with_model_error(C, Cs)
    assert np.all(np.linalg.eigvalsh(Cn - C) >= -1e-18)
    assert np.allclose(Cn, Cs, rtol=1e-9)  # Cs >= C here: the sum is Cs itself


def test_sectors_follow_the_arc_across_the_cut():
    ang = np.radians(np.linspace(120.0, 240.0, 600))  # lit arc through +-180 deg
    rc = np.stack([np.sin(ang), np.cos(ang)], 1) * 50.0
    g = sector_groups(rc, (0.0, 0.0), 12)
    assert np.all(np.diff(g) >= 0) and g[0] == 0 and g[-1] == 11
    assert np.bincount(g).min() == 50
