r"""The whole limb of a body whose limb shape is predicted: lit and dark limb, one elliptical sigmoid.

A stage for frames with a strong geometric prior (SPICE: camera, range, body orientation;
:mod:`jaxlimb.geometry.spice`), where the limb's shape in the image is known and its place
is what is measured (the pointing correction).  It measures the **whole** visible limb: the
lit limb (disc brighter than the sky) *and* the dark limb of a night side against a
brighter background -- the case of the Cassini high-phase frames of Enceladus, where the lit
crescent alone is an 80-deg arc on which centre and radius trade off (a circle through the
crescent alone came out 302-305 px against the 288 px the range says).

Steps (:func:`locate_whole_limb`):

1. the predicted-limb front end (:mod:`jaxlimb.imaging.predicted`): edge points of either
   polarity along the predicted ellipse, fitted with the predicted shape held;
2. the annulus ``|d| <= dr`` around that ellipse (``d`` the distance to it to first order,
   :math:`(\beta - \rho a)/|\nabla\beta|` in the notation of
   :func:`jaxlimb.models.ellipse_coords`), invalid pixels (mask) and clipped pixels
   (saturated: the frame's maximum held by >= 20 pixels) left out;
3. per angular bin the inner and outer levels (medians); a bin is kept when
   :math:`|I - O|` exceeds ``min_snr`` times its noise; intensities are normalised,
   :math:`z_n = (z - O)/(I - O)` (so a dark limb, :math:`I < O`, becomes the same 0-to-1
   step as a lit one) and weighted by :math:`|I - O|/C_{ref}` (the weighted residuals are DN
   residuals over :math:`C_{ref}`, as in :class:`jaxlimb.pipeline.refine.FitData`);
4. the elliptical sigmoid (ESF, Mortari et al. 2016) with the predicted axis ratio and angle
   held, centre, ``a``, ``k`` and the levels free; an outlier pass (Check 3) with a robust
   scale per 10-deg stretch of limb; the annulus is
   re-centred on the fit and the fit repeated;
5. the image of the body centre is the fitted ellipse centre plus the predicted offset
   between the body-centre image and the limb-ellipse centre (sub-pixel near the boresight);
   the on-axis radius and the range scale with :math:`a / a_{pred}`;
   covariance :math:`\hat\sigma^2 (J^\top J)^{-1}` of the fit mapped the same way.

6. a sphere with the Sun direction known, measured on its lit limb only (no dark-limb bins):
   the lit-limb pixels are refitted with the physical lunar-Lambert profile through the
   pipeline's own refit (:func:`jaxlimb.pipeline.profile_fit.fit_lunar_profile`), which removes the
   sigmoid's edge bias (0.35-0.5 px on short arcs);
7. the centre covariance: the larger of the pixel-independent and the cluster-robust one,
   plus an edge-model error (:data:`EDGE_MODEL_SIGMA_PX` through the arc's gains of
   :func:`jaxlimb.imaging.predicted.edge_bias_gain`);
8. lit and dark limb both measured: the model error of their split (the centre fitted on each
   polarity alone, :mod:`jaxlimb.pipeline.polarity_split`) is added to the centre covariance.

Bodies larger than the frame (:func:`locate_arc`): the visible arc's circle is found by RANSAC
with the radius the range predicts and the same stage runs from there; too-big only when no
arc is visible (``benchmarks/limb_arc.py``).

Accuracy (renders with exact truth, ``tests/mission/test_whole_limb.py``): uniform discs,
lit or dark against the sky, 0.006-0.06 px; a lit crescent whose brightness ramps from the
terminator to the limb over 10 px biases the sigmoid's edge by ~0.35 px along the Sun
direction (the flat-topped sigmoid is not the crescent's profile; the physical lunar-Lambert
profile of :mod:`jaxlimb.pipeline.profile` is not yet used in this stage).

Check 4: ``a`` must agree with the predicted one within ``3 u`` (hints
``expected_radius_uncertainty_frac``), else :class:`~jaxlimb.errors.RadiusInconsistentError`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..errors import ConfigError, ConvergenceError, RadiusInconsistentError, TooManyOutliersError
from ..geometry.camera import Camera
from ..imaging import Hints
from ..imaging.crop import estimate_noise
from ..imaging.predicted import LimbShape, edge_bias_gain, fit_shape, limb_edges, predicted_limb
from ..models import ELLIPSE, EllipseParams
from .options import LocateOptions
from .refine import K_INIT, FitData, RefineResult, _bin_median, _fixed, _run, predict
from .result import EllipseResult, LimbMeasurement

#: 1-sigma of a limb model's edge position error along the limb (px), per pattern of
#: :func:`~jaxlimb.imaging.predicted.edge_bias_gain`: the physical profile's accuracy on renders of its own
#: family (README: ~0.01-0.02 px).  On short arcs the profile's residual mismatch is larger -- the limb-arc
#: renders' centre errors divided by the arcs' gains are a first-harmonic edge error of -0.018 to -0.058 px
#: (``benchmarks/limb_arc.py``) -- and is covered there by the profile's own split-witness model error
#: (:func:`jaxlimb.pipeline.profile_fit.split_witness`); 0.04 px here as well counted it twice (RMS/sigma
#: 0.47/0.67 against 0.58/1.03).  It dominates the centre covariance of short arcs without that term.
EDGE_MODEL_SIGMA_PX = 0.02

#: Shape parameters held at the prediction.
_SHAPE_FIXED = ("theta", "rho")


def _ellipse_distance(shape: LimbShape, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance (px, + outside) to the ellipse to first order, and the eccentric anomaly."""
    x, y = shape.to_frame(coords)
    rho, a = shape.rho, shape.a
    beta = np.hypot(rho * x, y)
    grad = np.hypot(rho * rho * x, y) / np.where(beta > 0, beta, 1.0)
    return (beta - rho * a) / np.where(grad > 0, grad, 1.0), np.arctan2(y, rho * x)


def _annulus(img: np.ndarray, mask: np.ndarray | None, shape: LimbShape, dr: float):
    R, C = img.shape
    ext = shape.a + dr + 2
    cr, cc = shape.center_rc
    r0, r1 = max(0, int(cr - ext)), min(R, int(cr + ext) + 2)
    c0, c1 = max(0, int(cc - ext)), min(C, int(cc + ext) + 2)
    if r1 <= r0 or c1 <= c0:
        raise TooManyOutliersError("the predicted limb annulus lies outside the frame")
    rr, cc_ = np.mgrid[r0:r1, c0:c1]
    coords = np.stack([rr.ravel(), cc_.ravel()], axis=1).astype(np.float64)
    d, phi = _ellipse_distance(shape, coords)
    sel = np.abs(d) <= dr
    if mask is not None:
        sel &= mask[r0:r1, c0:c1].ravel()
    z = img[rr.ravel(), cc_.ravel()].astype(np.float64)
    sat = float(np.max(img))
    if np.count_nonzero(img == sat) >= 20:  # clipped pixels carry no edge position (pipeline.locate.saturation_level)
        sel &= z < sat
    return coords[sel], z[sel], d[sel], phi[sel]


def binned_limb_steps(img: np.ndarray, mask: np.ndarray | None, shape: LimbShape, dr: float, noise: float,
                      n_bins: int = 180, min_snr: float = 5.0):  # noqa: ANN201
    """The annulus ``|d| <= dr`` about ``shape`` in ``n_bins`` angular bins and each bin's limb step.

    Returns ``(coords, z, d, bins, step, significant, sky)``: the annulus pixels, their signed distance
    to the limb and bin index, the bins' inner-minus-outer median level (> 0 where the disc is brighter
    than the sky), whether it exceeds ``min_snr`` times its noise (two medians of >= 3 pixels), and the
    bins' outer (sky-side) median level.
    """
    coords, z, d, phi = _annulus(img, mask, shape, dr)
    bins = np.minimum(((phi + math.pi) / (2 * math.pi) * n_bins).astype(np.int64), n_bins - 1)
    inner, outer = d <= -0.5 * dr, d >= 0.5 * dr
    lev_in, n_in = _bin_median(bins[inner], z[inner], n_bins)
    lev_out, n_out = _bin_median(bins[outer], z[outer], n_bins)
    c = lev_in - lev_out
    n_min = np.minimum(n_in, n_out)
    sig = 1.2533 * noise * np.sqrt(2.0 / np.maximum(n_min, 1))  # std of a difference of two medians
    good = (n_min >= 3) & np.isfinite(c) & (np.abs(c) >= min_snr * np.maximum(sig, 1e-12))
    return coords, z, d, bins, c, good, lev_out


def select_whole_limb(img: np.ndarray, mask: np.ndarray | None, shape: LimbShape, dr: float, noise: float,
                      n_bins: int = 180, min_snr: float = 5.0) -> tuple[FitData, dict[str, int]]:
    """Level-normalised annulus data of both polarities (module docstring, steps 2-3).

    Raises
    ------
    TooManyOutliersError
        Fewer than 50 pixels in bins with a significant limb step.
    """
    coords, z, _, bins, c, good, lev_out = binned_limb_steps(img, mask, shape, dr, noise, n_bins, min_snr)
    keep = good[bins]
    if np.count_nonzero(keep) < 50:
        raise TooManyOutliersError(f"no significant limb step along the predicted limb ({int(good.sum())} of {n_bins} bins)")
    cb = c[bins[keep]]
    cref = float(np.median(np.abs(cb)))
    zn = (z[keep] - lev_out[bins[keep]]) / cb
    counts = {"bins_lit": int(np.count_nonzero(good & (c > 0))), "bins_dark": int(np.count_nonzero(good & (c < 0))),
              "bins": n_bins}
    return FitData(coords[keep], zn, np.abs(cb) / cref, float(np.nanmedian(lev_out[good])), cref), counts


def _stretches(shape: LimbShape, coords: np.ndarray, cluster_deg: float = 10.0) -> np.ndarray:
    """Index of the ``cluster_deg`` stretch of limb angle of each pixel."""
    _, phi = _ellipse_distance(shape, coords)
    m = max(1, int(round(360.0 / cluster_deg)))
    return np.minimum(((phi + math.pi) / (2 * math.pi) * m).astype(np.int64), m - 1)


def _outlier_pass_by_stretch(data: FitData, res, shape: LimbShape, opt: LocateOptions, fixed):
    """Check 3 with a robust scale per 10-deg stretch of limb (the lit and the dark limb differ in
    contrast by 10-100x, so one scale for all would call the lit limb's model error outliers)."""
    r = (data.z - predict(ELLIPSE, res.params, data.coords)) * data.weights
    cl = _stretches(shape, data.coords)
    bad = np.zeros(len(r), bool)
    for c in np.unique(cl):
        i = cl == c
        med = float(np.median(r[i]))
        sig = max(1.4826 * float(np.median(np.abs(r[i] - med))), 1e-12)
        bad[i] = np.abs(r[i] - med) > opt.outlier_sigma * sig
    nb = int(np.count_nonzero(bad))
    if nb > opt.max_outlier_fraction * len(r):
        raise TooManyOutliersError(
            f"Check 3: {nb} of {len(r)} limb pixels ({100.0 * nb / len(r):.1f} %) have residuals above "
            f"{opt.outlier_sigma:g} robust sigma of their stretch of limb; max_outlier_fraction = {opt.max_outlier_fraction:g}")
    if nb == 0:
        return res, data, 0
    d2 = data.subset(~bad)
    return _run(ELLIPSE, d2, res.params, opt, fixed), d2, nb


def _fit_pass(img, mask, shape: LimbShape, dr: float, noise: float, opt: LocateOptions):
    data, counts = select_whole_limb(img, mask, shape, dr, noise)
    init = EllipseParams(r0=shape.center_rc[0], c0=shape.center_rc[1], a=shape.a, theta=shape.theta, rho=shape.rho,
                         k=K_INIT, ymax=1.0, ymin=0.0)
    fixed = tuple(dict.fromkeys(_fixed(opt) + _SHAPE_FIXED))
    res = _run(ELLIPSE, data, init, opt, fixed)
    res, data, nb = _outlier_pass_by_stretch(data, res, shape, opt, fixed)
    p = res.params
    new = LimbShape((float(p.r0), float(p.c0)), float(p.a), shape.rho, shape.theta, shape.body_offset_rc)
    return RefineResult(res, data, nb, fixed), new, counts


def cluster_covariance(final: RefineResult, shape: LimbShape, cluster_deg: float = 10.0, h: float = 1e-5,
                       model=ELLIPSE) -> np.ndarray:
    r"""Cluster-robust (sandwich) covariance of the fit, pixels clustered by ``cluster_deg`` of limb angle.

    :math:`\mathrm{cov} = (J^\top W J)^{-1} \big(\sum_c g_c g_c^\top\big) (J^\top W J)^{-1}\,
    \tfrac{m}{m - 1}` with :math:`g_c = \sum_{i \in c} J_i^\top w_i^2 r_i` over the ``m`` clusters
    (Liang & Zeger 1986, *Biometrika* 73:13): errors may be correlated arbitrarily *within* a
    stretch of limb (texture, banding, compression blocks), which the pixel-independent
    :math:`\hat\sigma^2 (J^\top J)^{-1}` ignores.  ``J`` by central differences over ``free``.
    """
    p, free, data = final.fit.params, list(final.fit.free), final.data
    w = np.ones(len(data.z)) if data.weights is None else np.asarray(data.weights)
    r = data.z - predict(model, p, data.coords)
    J = np.empty((len(data.z), len(free)))
    for j, n in enumerate(free):
        v = float(getattr(p, n))
        J[:, j] = (predict(model, p.replace(**{n: v + h}), data.coords)
                   - predict(model, p.replace(**{n: v - h}), data.coords)) / (2 * h)
    Jw = J * w[:, None]
    bread = np.linalg.inv(Jw.T @ Jw)
    cl = _stretches(shape, data.coords, cluster_deg)
    m = int(cl.max()) + 1
    g = np.zeros((m, len(free)))
    np.add.at(g, cl, Jw * (w * r)[:, None])
    used = int(np.count_nonzero(np.bincount(cl, minlength=m)))
    meat = g.T @ g * (used / max(used - 1, 1))
    return bread @ meat @ bread


def _measurement(final: RefineResult, shape: LimbShape, pred: LimbShape, camera: Camera, hints: Hints,
                 extras: dict[str, Any]) -> LimbMeasurement:
    """Body-centre image, radius, LOS, range and covariance from the fit (module docstring, step 5)."""
    p = final.fit.params
    free = list(final.fit.free)
    scale = shape.a / pred.a
    r_eq_pred = pred.a * pred.rho  # ~ f tan(alpha) of the minor axis; the on-axis radius below
    rkm = hints.radius_km()
    f = camera.focal_px
    r_eq = f * math.tan(math.asin(rkm / hints.range_prior_km)) * scale if rkm else r_eq_pred * scale
    center = (float(p.r0) + shape.body_offset_rc[0], float(p.c0) + shape.body_offset_rc[1])
    names = {"r0": "center_r", "c0": "center_c", "a": "radius"}
    J = np.eye(len(free))
    if "a" in free:
        J[free.index("a"), free.index("a")] = r_eq / shape.a
    cov_fit = np.asarray(final.fit.covariance)
    cov_cl = cluster_covariance(final, shape)
    extras["covariance_model"] = "max(pixel-independent, cluster-robust over 10-deg stretches of limb)"
    extras["sigma_center_pixel_independent_px"] = [float(math.sqrt(cov_fit[i, i])) for i in (0, 1)]
    extras["sigma_center_cluster_robust_px"] = [float(math.sqrt(cov_cl[i, i])) for i in (0, 1)]
    cov_use = cov_cl if np.trace(cov_cl[:2, :2]) > np.trace(cov_fit[:2, :2]) else cov_fit
    cov = J @ cov_use @ J.T
    out_names = [names.get(n, n) for n in free]
    los = tuple(float(v) for v in camera.los(np.array(center)))
    range_km = float(hints.range_prior_km / scale)
    ell = EllipseResult(center_rc=(float(p.r0), float(p.c0)), semi_axes_px=(shape.a, shape.a * shape.rho),
                        angle_rad=float(shape.theta % math.pi))
    return LimbMeasurement(
        center_rc=center, radius_px=float(r_eq), ellipse=ell, k=float(p.k),
        ymax=float(final.data.offset + final.data.scale * float(p.ymax)),
        ymin=float(final.data.offset + final.data.scale * float(p.ymin)),
        covariance={a: {b: float(cov[i, j]) for j, b in enumerate(out_names)} for i, a in enumerate(out_names)},
        iterations=int(final.fit.n_steps), solver=final.fit.solver, front_end="predicted",
        n_pixels=int(final.fit.n_pixels), los_camera=los, range_km=range_km, extras=extras,
        selected_pixels_rc=final.coords,
    )


def locate_whole_limb(image: np.ndarray, camera: Camera, hints: Hints, options: LocateOptions | None = None, *,
                      mask: np.ndarray | None = None, search_px: float = 40.0) -> LimbMeasurement:
    """Locate a body of predicted limb shape from its whole limb (lit and dark; module docstring).

    Parameters
    ----------
    image
        2-D image (DN).
    camera
        Pinhole camera (distortion not handled here: :class:`~jaxlimb.errors.ConfigError`).
    hints
        Needs ``expected_center_rc``, ``range_prior_km`` and radii; ``R_body_to_camera``
        for a triaxial body (:meth:`jaxlimb.geometry.spice.SpiceGeometry.hints`).
    options
        :class:`LocateOptions` (solver, ``max_steps``, outlier settings, ``estimate_k``).
    mask
        Validity mask (``True`` = valid); invalid pixels are neither limb nor background.
    search_px
        Half-length of the edge search along the predicted limb's normals (the pointing
        uncertainty; default 40 px).

    Raises
    ------
    ConfigError
        Hints without the prediction, a camera with distortion.
    TooManyOutliersError, ConvergenceError, RadiusInconsistentError
        Checks 3-5.
    """
    opt = options or LocateOptions()
    # the shape is held and the start is the predicted limb: more LM steps than the circle's default
    opt = replace(opt, max_steps=max(opt.max_steps, 500))
    if camera.has_distortion:
        raise ConfigError("the whole-limb stage takes a pinhole camera (undistort the frame first)")
    img = np.asarray(image, dtype=np.float64)
    pred = predicted_limb(camera, hints)
    pts, step, ok = limb_edges(img, pred, mask=mask, search_px=search_px)
    coarse, used = fit_shape(pts, pred)
    noise = max(estimate_noise(img), 1e-9)
    shape, dr = coarse, 8.0
    res = counts = None
    for _ in range(3):
        res, shape, counts = _fit_pass(img, mask, shape, dr, noise, opt)
        dr = float(np.clip(4.5 * 1.7 / max(float(res.fit.params.k), 1e-6), 3.0, 8.0))
    assert res is not None and counts is not None
    u = hints.expected_radius_uncertainty_frac or 0.05
    if abs(shape.a / pred.a - 1.0) > 3 * u:
        raise RadiusInconsistentError(
            f"Check 4: the limb's semi-major axis {shape.a:.2f} px differs from the predicted {pred.a:.2f} px by more "
            f"than 3 x {u:g} (expected_radius_uncertainty_frac)")
    gain = edge_bias_gain(pts[used], shape)
    extras = {"edge_bias_gain": np.asarray(gain).tolist(), "edge_model_sigma_px": EDGE_MODEL_SIGMA_PX,
              "predicted_limb": {"center_rc": list(pred.center_rc), "semi_axes_px": [pred.a, pred.a * pred.rho],
                                 "angle_rad": pred.theta},
              "edge_fit": {"center_rc": list(coarse.center_rc), "a": coarse.a, "n_points": int(used.sum()),
                           "n_lit": int(np.count_nonzero(used & (step > 0))),
                           "n_dark": int(np.count_nonzero(used & (step < 0)))},
              "annulus_px": dr, "angular_bins": counts, "n_outliers": int(res.n_outliers),
              "scale_vs_predicted": shape.a / pred.a,
              "sigma_hat": math.sqrt(max(float(res.fit.sigma2), 0.0)) * res.data.scale,
              "n_masked": 0 if mask is None else int(mask.size - np.count_nonzero(mask))}
    if _sunlit_sphere(hints, counts):
        try:
            prof = _profile_refit(img, mask, shape, res, camera, hints, opt, noise)
            return _with_edge_model_error(_profile_measurement(prof, shape, camera, hints, extras), gain)
        except ConvergenceError as e:  # the sigmoid's answer stands; say why
            extras["profile_rejected"] = {"model": "lunar-lambert", "reason": str(e)}
    m = _with_edge_model_error(_measurement(res, shape, pred, camera, hints, extras), gain)
    return _with_polarity_split(m, img, mask, res, shape, dr, noise, opt)


def _with_polarity_split(m: LimbMeasurement, img, mask, res: RefineResult, shape: LimbShape, dr: float, noise: float,
                         opt: LocateOptions) -> LimbMeasurement:
    """Step 8: the model error of the lit/dark split (:mod:`jaxlimb.pipeline.polarity_split`) added to the
    centre covariance whenever both polarities are measured; its numbers in ``extras``."""
    from .polarity_split import polarity_split

    split = polarity_split(img, mask, res, shape, dr, noise, opt, tuple(res.fixed))
    m.extras["polarity_split"] = split
    if split is None:
        return m
    cov = {a: dict(row) for a, row in m.covariance.items()}
    M = np.asarray(split["model_error_cov_px2"])
    for i, a in enumerate(("center_r", "center_c")):
        for j, b in enumerate(("center_r", "center_c")):
            cov[a][b] += float(M[i, j])
    return replace(m, covariance=cov)


def _sunlit_sphere(hints: Hints, counts: dict[str, int]) -> bool:
    """A sphere (equal radii) with the Sun direction known, measured on its lit limb only."""
    radii = hints.body_radii_km
    if radii is None and hints.body is not None:
        from ..geometry.bodies import BODY_TABLE

        radii = BODY_TABLE[hints.body].radii_km if hints.body in BODY_TABLE else None
    return (hints.sun_dir_camera is not None and radii is not None and max(radii) - min(radii) < 1e-6 * max(radii)
            and counts["bins_dark"] == 0)


def _with_edge_model_error(m: LimbMeasurement, gain: np.ndarray) -> LimbMeasurement:
    """Add the edge-model error ``sigma_e^2 sum_k g_k g_k^T`` (:data:`EDGE_MODEL_SIGMA_PX`, the three
    patterns of :func:`~jaxlimb.imaging.predicted.edge_bias_gain`) to the centre covariance."""
    from dataclasses import replace as _replace

    cov = {a: dict(row) for a, row in m.covariance.items()}
    extra = EDGE_MODEL_SIGMA_PX**2 * np.asarray(gain).T @ np.asarray(gain)
    names = ("center_r", "center_c")
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            cov[a][b] += float(extra[i, j])
    return _replace(m, covariance=cov)


def _profile_refit(img, mask, shape: LimbShape, res: RefineResult, camera: Camera, hints: Hints, opt: LocateOptions,
                   noise: float, dr: float = 8.0):
    """The lunar-Lambert limb profile of :mod:`jaxlimb.pipeline.profile` on the lit limb (a sunlit
    sphere whose dark limb is not seen), through the pipeline's own refit
    (:func:`jaxlimb.pipeline.profile_fit.fit_lunar_profile`): removes the flat-topped sigmoid's edge bias."""
    from types import SimpleNamespace

    import time

    from ..models import CircleParams
    from .frame import Frame
    from .profile_fit import fit_lunar_profile

    data, _ = select_whole_limb(img, mask, shape, dr, noise)
    p = res.fit.params
    to_dn = lambda y: float(res.data.offset + res.data.scale * float(y))  # noqa: E731
    circle = CircleParams(r0=p.r0, c0=p.c0, radius=float(np.sqrt(shape.a * shape.a * shape.rho)), k=p.k,
                          ymax=to_dn(p.ymax), ymin=to_dn(p.ymin))
    z = img[data.coords[:, 0].astype(np.int64), data.coords[:, 1].astype(np.int64)]
    circ = SimpleNamespace(fit=SimpleNamespace(params=circle), coords=data.coords, data=FitData(data.coords, z, None, 0.0, 1.0))
    fitted, _ = fit_lunar_profile(Frame(img, camera, hints, opt, time.perf_counter()), circ, None)
    return fitted


def _profile_measurement(prof: RefineResult, shape: LimbShape, camera: Camera, hints: Hints,
                         extras: dict[str, Any]) -> LimbMeasurement:
    """Body centre, radius, LOS, range and covariance of the sphere profile fit (as ``locate`` maps them)."""
    from .sphere import sphere_from_ellipse_center

    p, free = prof.fit.params, list(prof.fit.free)
    f, pp = camera.focal_px, camera.principal_point_rc

    def out(x):
        s_ = sphere_from_ellipse_center(f, pp, (x[0], x[1]), x[2])
        return np.array([s_.body_center_rc[0], s_.body_center_rc[1], s_.radius_equivalent_px])

    x0 = np.array([float(p.r0), float(p.c0), float(p.a)])
    from ..models.lunar_lambert import glow_fields, profile_model

    cov_pix = np.asarray(prof.fit.covariance)
    cov_cl = cluster_covariance(prof, shape, model=profile_model(p))
    cov_fit = cov_cl if np.trace(cov_cl[:2, :2]) > np.trace(cov_pix[:2, :2]) else cov_pix
    extras["sigma_center_pixel_independent_px"] = [float(math.sqrt(cov_pix[i, i])) for i in (0, 1)]
    extras["sigma_center_cluster_robust_px"] = [float(math.sqrt(cov_cl[i, i])) for i in (0, 1)]
    h = 1e-4
    Jg = np.stack([(out(x0 + h * e) - out(x0 - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    gidx = [free.index(n) for n in ("r0", "c0", "a")]
    cov = Jg @ cov_fit[np.ix_(gidx, gidx)] @ Jg.T
    sph = sphere_from_ellipse_center(f, pp, (x0[0], x0[1]), x0[2])
    names = ["center_r", "center_c", "radius"]
    rkm = hints.radius_km()
    extras["profile"] = {"model": "lunar-lambert", "psf_sigma_px": float(p.sigma), "L": float(p.L),
                         "kappa": float(getattr(p, "kappa", 0.0)), **glow_fields(p)}
    return LimbMeasurement(
        center_rc=tuple(float(v) for v in sph.body_center_rc), radius_px=float(sph.radius_equivalent_px), ellipse=None,
        k=1.7 / math.sqrt(float(p.sigma) ** 2 + 1.0 / 12.0), ymax=float(p.ymin) + float(p.amp), ymin=float(p.ymin),
        covariance={a: {b: float(cov[i, j]) for j, b in enumerate(names)} for i, a in enumerate(names)},
        iterations=int(prof.fit.n_steps), solver=prof.fit.solver, front_end="predicted", n_pixels=int(prof.fit.n_pixels),
        los_camera=tuple(float(v) for v in sph.los), range_km=float(rkm / math.sin(sph.alpha_rad)) if rkm else None,
        extras=extras, selected_pixels_rc=prof.data.coords,
    )


def locate_arc(image: np.ndarray, camera: Camera, hints: Hints, options: LocateOptions | None = None, *,
               mask: np.ndarray | None = None) -> LimbMeasurement:
    """A body larger than the frame (close approach): the visible limb arc, shape from the hints.

    The arc's circle is found by RANSAC among the strongest gradients
    (:func:`jaxlimb.imaging.predicted.arc_center`) with the radius the range predicts; the
    limb ellipse of the body placed there (camera, radii, range, ``R_body_to_camera``) is then
    fitted as in :func:`locate_whole_limb` (shape held, centre and scale free), so the short
    arc's weak geometry shows in the covariance instead of in a free radius.

    Raises
    ------
    TooBigError
        No limb arc is visible (the body fills the frame).
    """
    from dataclasses import replace as _replace

    from ..imaging.predicted import arc_center

    img = np.asarray(image, dtype=np.float64)
    rkm = hints.radius_km()
    pr = camera.focal_px * math.tan(math.asin(rkm / hints.range_prior_km))
    u = hints.expected_radius_uncertainty_frac or 0.05
    c = arc_center(img, pr, u, mask=mask)
    m = locate_whole_limb(img, camera, _replace(hints, expected_center_rc=c), options, mask=mask)
    m.extras["arc_start_center_rc"] = list(c)
    return m


__all__ = ["locate_arc", "locate_whole_limb", "select_whole_limb"]
