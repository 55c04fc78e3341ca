"""The cluster-robust model-error term (jaxlimb.model_error)."""

import numpy as np

from jaxlimb.model_error import cluster_robust_bias_reduced, cluster_robust_covariance, sector_groups, with_model_error


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


def test_bias_reduced_sandwich_covers_few_unbalanced_clusters():
    """Six clusters of 4-11 points (the traced rays of a cloudy Earth with a glow: 42 rays in 6 sectors), a cluster
    effect 6x the pixel noise: the plain sandwich (CR1) under-covers by 30-50 %, the bias-reduced one (CR2, Bell &
    McCaffrey 2002) is within 30 % of the Monte-Carlo variance of the estimates."""
    sizes = [4, 11, 6, 6, 9, 6]
    g = np.repeat(np.arange(6), sizes)
    x = np.concatenate([np.linspace(-1 + 2 * k / 6, -1 + 2 * (k + 1) / 6, s, endpoint=False) for k, s in enumerate(sizes)])
    J = np.column_stack([np.ones_like(x), x, x * x])
    rng = np.random.default_rng(1)
    est, c1, c2 = [], [], []
    for _ in range(2000):
        y = 0.3 * rng.standard_normal(6)[g] + 0.05 * rng.standard_normal(g.size)
        b = np.linalg.lstsq(J, y, rcond=None)[0]
        r = y - J @ b
        est.append(b)
        c1.append(np.diag(cluster_robust_covariance(J, r, g)))
        c2.append(np.diag(cluster_robust_bias_reduced(J, r, g)))
    true = np.var(est, axis=0)
    assert np.all(np.mean(c1, axis=0) / true < 0.75)
    assert np.all(np.abs(np.mean(c2, axis=0) / true - 1.0) < 0.35)


def test_sectors_follow_the_arc_across_the_cut():
    ang = np.radians(np.linspace(120.0, 240.0, 600))  # lit arc through +-180 deg
    rc = np.stack([np.sin(ang), np.cos(ang)], 1) * 50.0
    g = sector_groups(rc, (0.0, 0.0), 12)
    assert np.all(np.diff(g) >= 0) and g[0] == 0 and g[-1] == 11
    assert np.bincount(g).min() == 50


def test_hausman_term_is_the_unexplained_part_of_a_difference():
    from jaxlimb.model_error import hausman_term, positive_part

    C = np.diag([1.0, 1.0])
    C_sub = np.diag([2.0, 2.0])
    # a difference the noise explains (|d|^2 <= C_sub - C): nothing
    assert np.allclose(hausman_term([0.5, -0.8], C_sub, C), 0.0)
    # a difference far beyond it: about d d^T, positive semi-definite
    W = hausman_term([10.0, 0.0], C_sub, C)
    assert np.isclose(W[0, 0], 99.0)
    assert np.all(np.linalg.eigvalsh(W) >= -1e-12)
    assert np.allclose(positive_part(np.diag([1.0, -2.0])), np.diag([1.0, 0.0]))


def test_split_witness_sees_a_misfit_the_same_all_along_the_limb():
    """A 1-D edge whose inner side is brighter than the model's flat top (a limb brightening the model
    has no parameter for): the sky-side subset moves the edge, the Hausman term carries it; with the
    exact model the term stays at the noise level."""
    from jaxlimb.model_error import hausman_term

    def fit(y, x):
        # model: ymin + amp * step blurred (erf) at x0, linearised around x0 = 0 by Gauss-Newton (3 iters)
        from scipy.special import erf

        p = np.array([0.0, 1.0, 0.0])  # x0, amp, ymin
        for _ in range(20):
            u = (p[0] - x) / 1.0
            f = p[2] + p[1] * 0.5 * (1 + erf(u / np.sqrt(2)))
            g = p[1] * np.exp(-0.5 * u * u) / np.sqrt(2 * np.pi)
            J = np.column_stack([g, 0.5 * (1 + erf(u / np.sqrt(2))), np.ones_like(x)])
            p = p + np.linalg.lstsq(J, y - f, rcond=None)[0]
        r = y - f
        return p, J, r, np.sum(r**2) / (x.size - 3) * np.linalg.inv(J.T @ J)

    from scipy.special import erf

    rng = np.random.default_rng(1)
    x = np.tile(np.linspace(-8, 6, 57), 40)  # x > 0: sky side
    truth = 0.5 * (1 + erf(-x / np.sqrt(2)))
    out = {}
    for name, extra in (("exact", 0 * x), ("brightened", 0.4 * np.exp(np.minimum(x, 0) / 0.7) * (x < 0))):
        y = truth + extra + 0.01 * rng.standard_normal(x.size)
        p, J, r, C = fit(y, x)
        W = 0.0
        for keep in (x > -2.0, x < 2.0):
            Jk, rk = J[keep], r[keep]
            Ai = np.linalg.pinv(Jk.T @ Jk)
            step = Ai @ Jk.T @ rk
            s2 = np.sum((rk - Jk @ step) ** 2) / (keep.sum() - 3)
            W = W + hausman_term(step[:1], s2 * Ai[:1, :1], C[:1, :1])[0, 0]
        out[name] = (p[0], C[0, 0], W)
    x0, c, w = out["brightened"]
    assert abs(x0) > 10 * np.sqrt(c)  # biased far beyond the noise-only sigma ...
    assert x0**2 / (c + w) < 9.0  # ... but not beyond the witness's
    assert out["exact"][2] < 4 * out["exact"][1]
