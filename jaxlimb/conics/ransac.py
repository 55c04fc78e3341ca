r"""RANSAC for circles with the index rotation of the Aerospace 2015 paper (§4.3).

Classic RANSAC (Fischler & Bolles) draws random minimal subsets.  The paper
replaces random draws by the *index rotation* of the pyramid star-identification
algorithm (Mortari et al. 2004): the triplets ``(i, j, k) = (i, i + dj, i + dj + dk)``
are visited as

.. code-block:: text

    for dj in 1 .. n-2:
        for dk in 1 .. n-dj-1:
            for i in 0 .. n-dj-dk-1:
                test (i, i+dj, i+dj+dk)

so that consecutive triplets never share an index, every triplet is visited at
most once, and (with points sorted by decreasing gradient) the strongest points
are combined first.  No random numbers are used: the result is deterministic.

For each triplet the circle through the three points (:func:`circle_from_three`)
is scored by the number of points within ``threshold`` px of it (the paper's
:math:`N_k` counts the points *farther* than :math:`d_{\min}`; minimising the
outliers is maximising the inliers).  Ties are broken by the MSAC cost
:math:`\sum \min(d_i^2, t^2)`.  Triplets whose radius lies outside
``radius_range`` (the expected radius of §3) score zero -- this is part of
Check 3 ("radii found by RANSAC not consistent with the expected radius").

The best model is then re-estimated with Taubin's fit (Eq. 26-35) on its
inliers, and the inlier set recomputed against the refined circle
(``refine_iterations`` times; the usual "locally optimised" RANSAC step).

Evaluation is vectorised in blocks of triplets: ``n_tests x m`` distances, with
``m = min(n, max_score_points)`` (decision: scoring on an even subsample).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, TooManyOutliersError
from .taubin import CircleFit, DegenerateFitError, circle_from_three, circle_residuals, fit_circle_taubin


@dataclass(frozen=True)
class RansacOptions:
    """Settings of :func:`ransac_circle`.

    Attributes
    ----------
    threshold
        Inlier distance :math:`d_{\\max}` in px (paper: ``5 p_r / 100``; §6 uses 4 px).  > 0.
    max_tests
        Number of triplets tested, :math:`N_T` (paper Eq. 17, capped at 500).  >= 1.
    min_inliers
        Fewest inliers accepted (Check 3).  >= 3.
    min_inlier_fraction
        Fewest inliers as a fraction of the points (Check 3).  In [0, 1].
    radius_range
        ``(r_min, r_max)`` in px: triplet circles outside it are rejected; ``None`` = any.
    refine_iterations
        Taubin re-fit / inlier re-selection rounds after the best triplet.  >= 0.
    max_score_points
        Triplets are scored on at most this many points (an even stride through the
        list, so the strongest-first order is kept); the refinement and the final
        inliers use all points.  Scoring 400 of 1500 points changes the inlier
        fraction estimate by ~2 % and cuts the cost 4x.  ``None`` = all.
    """

    threshold: float = 4.0
    max_tests: int = 500
    min_inliers: int = 8
    min_inlier_fraction: float = 0.0
    radius_range: tuple[float, float] | None = None
    refine_iterations: int = 3
    max_score_points: int | None = 400

    def __post_init__(self) -> None:
        if not (np.isfinite(self.threshold) and self.threshold > 0):
            raise ConfigError(f"RansacOptions.threshold must be a finite distance > 0 px, got {self.threshold!r}")
        if not (isinstance(self.max_tests, (int, np.integer)) and self.max_tests >= 1):
            raise ConfigError(f"RansacOptions.max_tests must be an integer >= 1, got {self.max_tests!r}")
        if not (isinstance(self.min_inliers, (int, np.integer)) and self.min_inliers >= 3):
            raise ConfigError(f"RansacOptions.min_inliers must be an integer >= 3, got {self.min_inliers!r}")
        if not (0.0 <= self.min_inlier_fraction <= 1.0):
            raise ConfigError(
                f"RansacOptions.min_inlier_fraction must be in [0, 1], got {self.min_inlier_fraction!r}"
            )
        if self.radius_range is not None:
            lo, hi = self.radius_range
            if not (0 <= lo < hi):
                raise ConfigError(f"RansacOptions.radius_range must be (lo, hi) with 0 <= lo < hi, got {self.radius_range!r}")
        if not (isinstance(self.refine_iterations, (int, np.integer)) and self.refine_iterations >= 0):
            raise ConfigError(f"RansacOptions.refine_iterations must be an integer >= 0, got {self.refine_iterations!r}")
        if self.max_score_points is not None and not (
            isinstance(self.max_score_points, (int, np.integer)) and self.max_score_points >= 10
        ):
            raise ConfigError(f"RansacOptions.max_score_points must be an integer >= 10 or None, got {self.max_score_points!r}")


@dataclass(frozen=True)
class RansacResult:
    """Outcome of :func:`ransac_circle`; falsy when RANSAC failed.

    Attributes
    ----------
    ok
        True when a circle with enough inliers was found.
    inliers
        Boolean mask ``(n,)`` of the inliers of ``circle`` (all False on failure).
    circle
        Taubin fit on the inliers, or ``None`` on failure.
    n_tests
        Number of triplets tested.
    best_triplet
        Indices of the best triplet, or ``None``.
    reason
        Empty on success; why it failed otherwise.
    """

    ok: bool
    inliers: np.ndarray = field(repr=False)
    circle: CircleFit | None
    n_tests: int
    best_triplet: tuple[int, int, int] | None = None
    reason: str = ""

    def __bool__(self) -> bool:
        return bool(self.ok)

    @property
    def n_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))


def pyramid_triplets(n: int, max_count: int) -> np.ndarray:
    """The first ``max_count`` index triplets of the pyramid index rotation, shape ``(m, 3)``.

    ``m = min(max_count, C(n, 3))``.  See the module docstring for the order.
    """
    if n < 3 or max_count <= 0:
        return np.zeros((0, 3), dtype=np.int64)
    blocks = []
    count = 0
    for dj in range(1, n - 1):
        for dk in range(1, n - dj):
            m = n - dj - dk
            if m <= 0:
                break
            take = min(m, max_count - count)
            i = np.arange(take, dtype=np.int64)
            blocks.append(np.stack([i, i + dj, i + dj + dk], axis=1))
            count += take
            if count >= max_count:
                return np.concatenate(blocks)
    return np.concatenate(blocks) if blocks else np.zeros((0, 3), dtype=np.int64)


def ransac_circle(
    points_rc: np.ndarray,
    options: RansacOptions | None = None,
    *,
    raise_on_failure: bool = False,
) -> RansacResult:
    """Robust circle fit: RANSAC with index rotation, then Taubin on the inliers.

    Parameters
    ----------
    points_rc
        ``(n, 2)`` candidate points ``(row, col)``, ideally sorted by decreasing
        edge strength (the rotation combines the first points first).
    options
        :class:`RansacOptions`.
    raise_on_failure
        Raise :class:`~jaxlimb.errors.TooManyOutliersError` instead of returning a
        falsy result.

    Returns
    -------
    RansacResult
        Falsy (``ok=False``) when fewer than ``min_inliers`` (or
        ``min_inlier_fraction``) points agree with any tested circle.
    """
    opt = options or RansacOptions()
    p = np.asarray(points_rc, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise DegenerateFitError(f"ransac_circle: points_rc must have shape (n, 2), got {p.shape}")
    n = p.shape[0]
    none = np.zeros(n, dtype=bool)

    def fail(reason: str, n_tests: int = 0) -> RansacResult:
        if raise_on_failure:
            raise TooManyOutliersError(f"RANSAC circle: {reason}")
        return RansacResult(False, none, None, n_tests, None, reason)

    need = max(opt.min_inliers, int(np.ceil(opt.min_inlier_fraction * n)), 3)
    if n < need:
        return fail(f"{n} candidate points, at least {need} needed (min_inliers={opt.min_inliers}, "
                    f"min_inlier_fraction={opt.min_inlier_fraction})")
    trip = pyramid_triplets(n, int(opt.max_tests))
    thr = float(opt.threshold)
    n_tests = int(trip.shape[0])
    best_t = _best_triplet(p, trip, opt)
    if best_t is None:
        return fail("no tested triplet gave a circle within the radius range", n_tests)
    inliers, fit = _refine_inliers(p, best_t[3], best_t[4], opt)
    if fit is None:
        return fail("the Taubin fit of the best RANSAC inliers is degenerate", n_tests)
    n_in = int(inliers.sum())
    if n_in < need:
        return fail(
            f"best circle has {n_in} inliers of {n} points within {thr:.3g} px; at least {need} needed "
            f"(min_inliers={opt.min_inliers}, min_inlier_fraction={opt.min_inlier_fraction})",
            n_tests,
        )
    fit = fit_circle_taubin(p[inliers])
    return RansacResult(True, inliers, fit, n_tests, best_t[:3], "")


def _best_triplet(p: np.ndarray, trip: np.ndarray, opt: RansacOptions) -> tuple | None:
    """The tested circle (through a triplet, within the radius range) with the most inliers, ties broken by
    the truncated squared residual (MSAC); scored on at most ``max_score_points`` points, in blocks of
    about 2e6 distances.  Returns ``(i, j, k, centre, radius)`` or ``None``."""
    thr = float(opt.threshold)
    n = p.shape[0]
    if opt.max_score_points is not None and n > opt.max_score_points:
        ps = p[np.linspace(0, n - 1, int(opt.max_score_points)).round().astype(np.int64)]
    else:
        ps = p
    best_score = (-1, np.inf)
    best_t = None
    block = max(1, int(2_000_000 // max(ps.shape[0], 1)))
    for s in range(0, trip.shape[0], block):
        t = trip[s : s + block]
        c, r = circle_from_three(p[t[:, 0]], p[t[:, 1]], p[t[:, 2]])
        valid = np.isfinite(r)
        if opt.radius_range is not None:
            valid &= (r >= opt.radius_range[0]) & (r <= opt.radius_range[1])
        if not valid.any():
            continue
        cv, rv, tv = c[valid], r[valid], t[valid]
        d = np.abs(np.hypot(ps[None, :, 0] - cv[:, 0:1], ps[None, :, 1] - cv[:, 1:2]) - rv[:, None])
        cnt = (d <= thr).sum(1)
        cost = np.minimum(d * d, thr * thr).sum(1)
        k = np.lexsort((cost, -cnt))[0]
        score = (int(cnt[k]), float(cost[k]))
        if score[0] > best_score[0] or (score[0] == best_score[0] and score[1] < best_score[1]):
            best_score = score
            best_t = (int(tv[k, 0]), int(tv[k, 1]), int(tv[k, 2]), cv[k].copy(), float(rv[k]))
    return best_t


def _refine_inliers(p: np.ndarray, center: np.ndarray, radius: float,
                    opt: RansacOptions) -> tuple[np.ndarray, CircleFit | None]:
    """Taubin fit of the inliers and re-selection, up to ``refine_iterations`` times or until the inlier
    set is stable; a degenerate fit or one outside the radius range stops it (``fit=None`` if the first)."""
    thr = float(opt.threshold)
    inliers = np.abs(circle_residuals(p, center, radius)) <= thr
    fit: CircleFit | None = None
    for _ in range(int(opt.refine_iterations) + 1):
        if inliers.sum() < 3:
            break
        try:
            f = fit_circle_taubin(p[inliers])
        except DegenerateFitError:
            break
        if opt.radius_range is not None and not (opt.radius_range[0] <= f.radius <= opt.radius_range[1]):
            break
        fit = f
        new = np.abs(circle_residuals(p, f.center_rc, f.radius)) <= thr
        if np.array_equal(new, inliers) or new.sum() < 3:
            break
        inliers = new
    return inliers, fit


__all__ = ["RansacOptions", "RansacResult", "pyramid_triplets", "ransac_circle"]
