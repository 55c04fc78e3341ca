"""The round limb's sigmoid fits on an annulus (Aerospace 2015 §5-6; Mortari et al. 2016 §V-C): the circular sigmoid,
the ESF with the shape of a sphere's image, the free ESF; the levels' start, and Check 3's outlier pass (with the
local misfit of an edge model's shape told from outliers)."""

from __future__ import annotations

import numpy as np

from ...errors import TooManyOutliersError
from ...fitting import LimbFit
from ...geometry.sphere_image import SphereImage, sphere_from_ellipse_center
from ...models import CIRCLE, CircleParams, ELLIPSE, EllipseParams
from ..checks import MAX_OUTLIER_FRACTION, OUTLIER_SIGMA
from ..options import LocateOptions
from ..sigmoid import K_INIT, levels_held, predict, replace_params, run_fit
from ..stages import AnnulusSelection, FitData, RefineResult


#: The steepness (1/px) held when ``estimate_k`` is off (the illuminated-ellipsoid paper §VI, Table 1).
K_FIXED = 3.0


def fit_data(sel: AnnulusSelection) -> FitData:
    """The level-normalised data of ``sel`` (each angular bin divided by its contrast; :class:`FitData`).

    Parameters
    ----------
    sel : AnnulusSelection
        Without per-pixel bin levels the data are the raw DN (unit weights).

    Returns
    -------
    FitData
        ``z_n = (z - O_bin) / (I_bin - O_bin)``, weights ``(I_bin - O_bin) / C_ref``, offset the median outer
        level and scale ``C_ref`` (the median contrast, DN).
    """
    if sel.pixel_inner is None or sel.pixel_outer is None:
        return FitData(sel.coords, sel.z, None, 0.0, 1.0)
    c = sel.pixel_inner - sel.pixel_outer
    cref = float(np.median(c))
    zn = (sel.z - sel.pixel_outer) / c
    return FitData(sel.coords, zn, c / cref, float(np.median(sel.pixel_outer)), cref)


def initial_levels(sel: AnnulusSelection, data: FitData, options: LocateOptions) -> tuple[float, float, float]:
    """The fit's start ``(k, ymax, ymin)``: :data:`~jaxlimb.pipeline.sigmoid.K_INIT` and the levels (1, 0 for
    level-normalised data) with ``estimate_k``; else :data:`K_FIXED` and the means of the pixels within 1 px of the
    annulus' inner and outer radii (held in the fit, the illuminated-ellipsoid paper's setting, §VI).

    Parameters
    ----------
    sel : AnnulusSelection
    data : FitData
        The data to be fitted (:func:`fit_data`).
    options : LocateOptions

    Returns
    -------
    k : float
        Steepness (1/px).
    ymax, ymin : float
        Inside and outside levels, in the units of ``data.z``.
    """
    if options.estimate_k:
        if data.weights is not None:
            return K_INIT, 1.0, 0.0
        return K_INIT, sel.inner_level, sel.outer_level
    d = np.hypot(data.coords[:, 0] - sel.center_rc[0], data.coords[:, 1] - sel.center_rc[1])
    e_in = d <= sel.radius - sel.dr + 1.0
    e_out = d >= sel.radius + sel.dr - 1.0
    ymax = float(np.mean(data.z[e_in])) if e_in.any() else float(np.max(data.z))
    ymin = float(np.mean(data.z[e_out])) if e_out.any() else float(np.min(data.z))
    return K_FIXED, ymax, ymin


def outlier_pass(model, data: FitData, res: LimbFit, options: LocateOptions, fixed) -> tuple[LimbFit, FitData, int]:
    """Check 3: pixels whose residual exceeds :data:`~jaxlimb.pipeline.checks.OUTLIER_SIGMA` robust sigmas are dropped
    and the fit repeated; more than :data:`~jaxlimb.pipeline.checks.MAX_OUTLIER_FRACTION` of them (beyond the local
    misfit of the edge model's shape, :func:`local_misfit`) is a :class:`~jaxlimb.errors.TooManyOutliersError`.

    Parameters
    ----------
    model : LimbModel
        The fitted model (CSF or ESF).
    data : FitData
    res : LimbFit
        The fit on all of ``data``.
    options : LocateOptions
    fixed : tuple of str
        Parameters held fixed.

    Returns
    -------
    fit : LimbFit
        The refit without the outliers (``res`` when there are none).
    data : FitData
        The pixels kept.
    n_outliers : int
    """
    pred = predict(model, res.params, data.coords)
    r = data.z - pred
    if data.weights is not None:
        r = r * data.weights
    sig = _robust_sigma(r)
    bad = np.abs(r) > OUTLIER_SIGMA * sig
    nb = int(np.count_nonzero(bad))
    n = data.z.shape[0]
    if nb > MAX_OUTLIER_FRACTION * n:
        # a misfit of the edge model's shape (a bright rim) is not an outlier: test what is left about it (same sigma)
        bad = np.abs(r - local_misfit(r, data.coords, res.params)) > OUTLIER_SIGMA * sig
        nl = int(np.count_nonzero(bad))
        if nl > MISFIT_OUTLIER_SHARE * MAX_OUTLIER_FRACTION * n:
            raise TooManyOutliersError(
                f"Check 3: {nb} of {n} annulus pixels ({100.0 * nb / n:.1f} %) have residuals above "
                f"{OUTLIER_SIGMA:g} robust sigma, above the {MAX_OUTLIER_FRACTION:g} allowed "
                f"({100.0 * nl / n:.1f} % about their neighbourhood's misfit, above {MISFIT_OUTLIER_SHARE:g} of it)"
            )
        nb = nl
    if nb == 0:
        return res, data, 0
    d2 = data.subset(~bad)
    res2 = run_fit(model, d2, res.params, options, fixed)
    return res2, d2, nb


def _robust_sigma(r: np.ndarray) -> float:
    """1.4826 MAD of the residuals ``r`` (at least 1e-12 of their largest)."""
    mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    return max(mad, 1e-12 * max(1.0, float(np.max(np.abs(r)))))


MISFIT_BIN_PX = 1.0
"""Width (px) of the distance bins of :func:`local_misfit`."""


MISFIT_SECTORS = 8
"""Angular sectors (about the fitted centre) of :func:`local_misfit`."""


MISFIT_OUTLIER_SHARE = 0.25
"""About :func:`local_misfit`, at most this share of :data:`~jaxlimb.pipeline.checks.MAX_OUTLIER_FRACTION` of the annulus may be outliers (else
Check 3 fails).  Measured (5 sigma of the plain residuals): the Minnaert crescent of :func:`local_misfit` 1.2 % (24 %
plain), the bright square of ``test_check3_too_many_outliers`` 10-11 % (23 % plain) with 1-8 sectors."""


def local_misfit(r: np.ndarray, coords: np.ndarray, params) -> np.ndarray:
    """The systematic part of the residuals ``r``: the median residual of each pixel's cell of
    :data:`MISFIT_BIN_PX` in distance from the fitted centre by :data:`MISFIT_SECTORS` sectors about it.

    Why: Check 3's outliers are stars, hot pixels and cosmic rays, pixels unlike their neighbours.  A limb whose
    radial shape the sigmoid cannot follow misfits whole bands of the annulus instead, each pixel by about as much
    as
    its neighbours: the bright rim of a Minnaert crescent (``benchmarks/families.py`` Moon ``minnaert`` 4 of seed
    2028,
    38 px at phase 134 deg, 8 bit) leaves the bands 1-2 px and 5-6 px inside the limb 5-9 robust sigmas off (the
    sky's noise sets the MAD), 24 % of the annulus; about their cells' medians 1.2 % are, and the profile refit that
    follows fits that rim (its Minnaert exponent).  Used only when the plain test fails Check 3, with the plain
    test's sigma and a smaller share (:data:`MISFIT_OUTLIER_SHARE`): a model wrong everywhere (a bright square,
    ``test_check3_too_many_outliers``) leaves its cells' pixels far apart still.

    Parameters
    ----------
    r : np.ndarray (n,)
        Residuals (weighted, as tested).
    coords : np.ndarray (n, 2)
        Pixels ``(row, col)``.
    params : CircleParams or EllipseParams
        The fit (centre ``r0, c0`` and ``radius`` or ``a``).

    Returns
    -------
    np.ndarray (n,)
        Each pixel's cell median.
    """
    c = np.asarray(coords, float)
    r0, c0 = float(params.r0), float(params.c0)
    rad = float(params.radius) if isinstance(params, CircleParams) else float(params.a)
    d = np.floor((np.hypot(c[:, 0] - r0, c[:, 1] - c0) - rad) / MISFIT_BIN_PX).astype(np.int64)
    sec = np.floor((np.arctan2(c[:, 1] - c0, c[:, 0] - r0) + np.pi) / (2 * np.pi) * MISFIT_SECTORS).astype(np.int64)
    cell = (d - d.min()) * (MISFIT_SECTORS + 1) + np.clip(sec, 0, MISFIT_SECTORS)
    out = np.zeros_like(r)
    order = np.argsort(cell, kind="stable")
    bounds = np.flatnonzero(np.diff(cell[order])) + 1
    for idx in np.split(order, bounds):
        out[idx] = np.median(r[idx])
    return out


def fit_circle_annulus(sel: AnnulusSelection, options: LocateOptions) -> RefineResult:
    """Circular sigmoid (CSF, Eq. 16 of the illuminated-ellipsoid paper) on the selected pixels, from the annulus
    circle;
    outlier pass.

    Parameters
    ----------
    sel : AnnulusSelection
    options : LocateOptions
        Solver, ``max_steps``, ``estimate_k``.

    Returns
    -------
    RefineResult
        The fit on the level-normalised data (:func:`fit_data`), outliers removed.
    """
    fixed = levels_held(options)
    data = fit_data(sel)
    k0, ymax0, ymin0 = initial_levels(sel, data, options)
    init = CircleParams(r0=sel.center_rc[0], c0=sel.center_rc[1], radius=sel.radius, k=k0, ymax=ymax0, ymin=ymin0)
    res = run_fit(CIRCLE, data, init, options, fixed)
    res, data, nb = outlier_pass(CIRCLE, data, res, options, fixed)
    return RefineResult(res, data, nb, fixed)


def sphere_shape(focal_px: float, principal_point_rc, center_rc, a: float) -> SphereImage:
    """Shorthand for :func:`~jaxlimb.geometry.sphere_image.sphere_from_ellipse_center`.

    Parameters
    ----------
    focal_px : float
        Focal length (px).
    principal_point_rc : (float, float)
    center_rc : (float, float)
        Limb ellipse centre (ideal px).
    a : float
        Its semi-major axis (px).

    Returns
    -------
    SphereImage
    """
    return sphere_from_ellipse_center(focal_px, principal_point_rc, center_rc, a)


def fit_sphere_annulus(
    data: FitData,
    circle: CircleParams,
    focal_px: float,
    principal_point_rc,
    options: LocateOptions,
    n_iter: int = 2,
) -> RefineResult:
    """Elliptical sigmoid with the axis ratio and orientation of the image of a sphere.

    The ESF (the illuminated-ellipsoid paper, Sec. V-C) is fitted with ``rho`` and ``theta`` held at the values of
    the sphere image whose ellipse centre and radial semi-axis are the current estimate
    (:func:`~jaxlimb.geometry.sphere_image.sphere_from_ellipse_center`), free ``r0, c0, a`` (and
    ``k, ymax, ymin`` unless fixed); then ``rho``, ``theta`` are recomputed from the new
    estimate and the fit repeated (``n_iter`` fits in all).  ``rho`` changes by
    ~``1e-4 x`` the centre change in px at the corner of the default camera, so after
    the second fit the held shape is exact to ~1e-8 px.

    Parameters
    ----------
    data : FitData
        Pixels in pinhole (undistorted) coordinates.
    circle : CircleParams
        The circular sigmoid's fit, the start (its radius taken as the mean of the semi-axes).
    focal_px : float
        Focal length (px).
    principal_point_rc : (float, float)
    options : LocateOptions
    n_iter : int
        Number of fits.

    Returns
    -------
    RefineResult
        The last fit (no outlier pass) and the :class:`~jaxlimb.geometry.sphere_image.SphereImage` of its estimate.
    """
    fixed = ("theta", "rho") + levels_held(options)
    sph = sphere_shape(focal_px, principal_point_rc, (float(circle.r0), float(circle.c0)), float(circle.radius))
    # a circle fitted to an ellipse returns ~ the mean radius (a + b)/2
    a0 = 2.0 * float(circle.radius) / (1.0 + sph.rho)
    sph = sphere_shape(focal_px, principal_point_rc, (float(circle.r0), float(circle.c0)), a0)
    p = EllipseParams(r0=circle.r0, c0=circle.c0, a=a0, theta=sph.angle_rad, rho=sph.rho, k=circle.k,
                      ymax=circle.ymax, ymin=circle.ymin)
    res = None
    for _ in range(n_iter):
        res = run_fit(ELLIPSE, data, p, options, fixed)
        q = res.params
        sph = sphere_shape(focal_px, principal_point_rc, (float(q.r0), float(q.c0)), float(q.a))
        p = replace_params(q, theta=sph.angle_rad, rho=sph.rho)
    assert res is not None
    return RefineResult(res, data, 0, fixed, sphere=sph)


def fit_ellipse_annulus(data: FitData, start: EllipseParams, options: LocateOptions) -> RefineResult:
    """Elliptical sigmoid with every geometric parameter free (``rho``, ``theta`` too); outlier pass.

    Parameters
    ----------
    data : FitData
    start : EllipseParams
    options : LocateOptions

    Returns
    -------
    RefineResult
    """
    fixed = levels_held(options)
    res = run_fit(ELLIPSE, data, start, options, fixed)
    res, data2, nb = outlier_pass(ELLIPSE, data, res, options, fixed)
    return RefineResult(res, data2, nb, fixed)


__all__ = ["MISFIT_BIN_PX", "MISFIT_OUTLIER_SHARE", "MISFIT_SECTORS", "fit_circle_annulus", "fit_data", "fit_ellipse_annulus", "fit_sphere_annulus", "initial_levels", "local_misfit", "outlier_pass", "sphere_shape"]
