r"""Covariance and checks of a converged registration (typed failures, CLI exit 3).

**Covariance** ``sigma^2 (A^T A)^{-1}`` of the last linear solve, with ``sigma^2`` the residual variance,
mapped to ``(row, col)`` by ``1/a``, plus the cluster-robust model-error term of
:mod:`jaxlimb.model_error` over position-angle sectors (:attr:`.RegisterOptions.model_error`: an
albedo the model does not know biases the centre, and the term makes the reported sigma say so), plus a
floor for the rendering's own quantisation.

**Checks** (:class:`~jaxlimb.errors.MatchError`): the excess of the residual over the background noise
relative to the body's contrast, the overlap (IoU) of the observed and predicted lit figures, a finite
answer, and the centre's sigma (:func:`jaxlimb._validate.check_center_sigma`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..._validate import check_center_sigma
from ...model_error import cluster_robust_from_normal, positive_part, sector_groups
from ...errors import ConvergenceError, MatchError
from .design import Solve
from .gauss_newton import GNState, Problem
from .options import RegisterOptions, RegisterResult
from .pyramid import pose

_MIN_IOU = 0.9  # smallest accepted overlap of the observed and predicted lit figures
_IOU_MISFIT = 1.0  # the misfit band of overlap() in units of the residual excess (times the contrast)
_MODEL_ERROR_SECTORS = 16  # position-angle sectors of the model-error term
# the model-error term is multiplied by this squared: sixteen sectors of a smooth misfit are not independent,
# and the sandwich alone under-reports (benchmarks/irregular_independent.py)
_MODEL_ERROR_SCALE = 2.5
# standard deviation (px, per axis) for the rendering's quantisation (coverage steps of 1/16 at 4x4 sub-pixels):
# the Monte Carlo scatter of a Thebe frame at 2 DN noise
_MODEL_FLOOR_PX = 0.004


def overlap(obs: np.ndarray, model_flat: np.ndarray, thr: float, sigma: float, misfit: float = 0.0) -> float:
    """IoU of the observed figure and the fitted model thresholded like the frame.

    Pixels whose model value lies within 3 noise sigmas plus ``misfit`` (DN) of the threshold (a dim
    terminator, an edge) can fall either way by noise or by the model's accepted misfit alone and are left
    out.  ``misfit`` is the fit's residual excess times its contrast: the background of an 8-bit frame can
    be noiseless (MAD 0) while the body's own photon and quantisation noise and the misfit of a real surface
    are not.  Twice that band lets another body's model through (``tests/irregular/test_locate_los.py``).

    Parameters
    ----------
    obs : np.ndarray (h, w) of bool
        Observed lit figure in the window.
    model_flat : np.ndarray (h * w,)
        Fitted model radiance (DN), flattened row-major.
    thr : float
        The segmentation's grey level (DN).
    sigma : float
        Background noise (DN); ``nan``: none.
    misfit : float
        Accepted model misfit (DN) widening the left-out band.

    Returns
    -------
    float
        Intersection over union of the two figures, in [0, 1].
    """
    model = model_flat.reshape(obs.shape)
    sure = np.abs(model - thr) > 3.0 * (sigma if math.isfinite(sigma) else 0.0) + misfit
    pred = (model > thr) & sure
    o = obs & sure
    return float(np.logical_and(pred, o).sum()) / max(float(np.logical_or(pred, o).sum()), 1.0)


def background_sigma(image: np.ndarray, mask: np.ndarray, lo, hi) -> float:  # type: ignore[no-untyped-def]
    """Robust (MAD) noise of the background pixels of the window, away from the figure.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Frame (DN).
    mask : np.ndarray (rows, cols)
        Lit figure; pixels within 3 px of it are left out.
    lo, hi : np.ndarray (2,) of int
        Window, first and last pixel ``(row, col)``.

    Returns
    -------
    float
        ``1.4826 MAD`` of the background (DN); ``nan`` with fewer than 50 background pixels.
    """
    win = (slice(lo[0], hi[0] + 1), slice(lo[1], hi[1] + 1))
    far = cv2.dilate(np.ascontiguousarray(mask, dtype=np.uint8), np.ones((7, 7), np.uint8))[win] == 0
    vals = image[win][far]
    if vals.size < 50:
        return float("nan")
    return float(1.4826 * np.median(np.abs(vals - np.median(vals))))


def _with_sector_model_error(sol: Solve, res: np.ndarray, P: np.ndarray, cov: np.ndarray, a: float) -> np.ndarray:
    """The centre covariance with the cluster-robust model-error term (pixels grouped in position-angle sectors
    about ``P``)."""
    rr, cc = np.mgrid[sol.lo[0] : sol.hi[0] + 1, sol.lo[1] : sol.hi[1] + 1]
    groups = sector_groups(np.stack([rr.ravel(), cc.ravel()], axis=1).astype(float), P, _MODEL_ERROR_SECTORS)
    C_s = cluster_robust_from_normal(sol.At, sol.N, res, groups, _MODEL_ERROR_SECTORS)
    return cov + _MODEL_ERROR_SCALE**2 * positive_part(C_s[2:4, 2:4] / a**2 - cov)


def center_covariance(sol: Solve, P: np.ndarray, options: RegisterOptions) -> tuple[np.ndarray, float]:
    """Covariance of the centre (module docstring) and the residual variance of the solve ``sol``.

    Parameters
    ----------
    sol : Solve
        The last (sharp, full-resolution) linear solve.
    P : np.ndarray (2,)
        Body-centre image, px ``(row, col)``: the centre of the model-error sectors.
    options : RegisterOptions
        ``model_error`` switches the sector term on.

    Returns
    -------
    cov : np.ndarray (2, 2)
        Covariance of the centre, px^2 ``(row, col)``.
    s2 : float
        Residual variance (DN^2).

    Raises
    ------
    ConvergenceError
        Singular normal matrix.
    """
    a = float(sol.beta[0])
    res = sol.y - np.einsum("i,ij->j", sol.beta, sol.At)
    dof = max(res.size - sol.At.shape[0], 1)
    s2 = float(np.einsum("i,i->", res, res)) / dof
    try:
        cov_beta = s2 * np.linalg.inv(sol.N)
    except np.linalg.LinAlgError:
        raise ConvergenceError("registration: singular normal matrix") from None
    cov = cov_beta[2:4, 2:4] / a**2
    if options.model_error:
        cov = _with_sector_model_error(sol, res, P, cov, a)
    return cov + _MODEL_FLOOR_PX**2 * np.eye(2), s2


def _check(excess: float, iou: float, P: np.ndarray, cov: np.ndarray, options: RegisterOptions) -> None:
    if not np.all(np.isfinite(P)) or not np.all(np.isfinite(cov)):
        raise ConvergenceError("registration produced a non-finite centre or covariance")
    if excess > options.max_excess_frac:
        raise MatchError(
            f"the registered model leaves a residual of {excess:.3f} of the body's contrast above the noise"
            f" (limit {options.max_excess_frac}): the shape model, attitude or Sun direction does not fit the frame"
        )
    if iou < _MIN_IOU:
        raise MatchError(f"the predicted and observed lit figures overlap by IoU {iou:.3f} (limit {_MIN_IOU})")
    check_center_sigma(cov, options.max_center_sigma_px)


def finish_registration(problem: Problem, threshold: float, st: GNState, ncc: float) -> RegisterResult:
    """Covariance and checks (module docstring) from the last (sharp, full-resolution) solve of ``st``.

    Parameters
    ----------
    problem : Problem
        The registration problem (frame, camera, lit figure, options).
    threshold : float
        The segmentation's grey level (DN).
    st : GNState
        Converged Gauss-Newton state.
    ncc : float
        Cross-correlation of the start (reported only).

    Returns
    -------
    RegisterResult
        Centre, line of sight, range, covariance and the quality measures.

    Raises
    ------
    ConvergenceError, MatchError, CenterTooUncertainError
        No iteration or a non-finite answer; residual excess or overlap beyond the limits; centre sigma too wide.
    """
    sol = st.last
    if sol is None:
        raise ConvergenceError("registration: no iteration was made")
    image, camera, mask = problem.pyramid[1]
    P, D = st.P, st.D
    a, b = float(sol.beta[0]), float(sol.beta[1])
    cov, s2 = center_covariance(sol, P, problem.options)
    sigma = background_sigma(image, mask, sol.lo, sol.hi)
    excess = math.sqrt(max(s2 - (sigma**2 if math.isfinite(sigma) else 0.0), 0.0)) / a
    obs = mask[sol.lo[0] : sol.hi[0] + 1, sol.lo[1] : sol.hi[1] + 1] > 0
    iou = overlap(obs, sol.fitted_radiance(), threshold, sigma, _IOU_MISFIT * excess * a)
    _check(excess, iou, P, cov, problem.options)
    return RegisterResult(
        center_rc=np.asarray(P, dtype=float),
        los_camera=np.asarray(camera.los(P), dtype=float),  # type: ignore[attr-defined]
        range_km=float(D),
        t_camera=pose(camera, P, D),
        covariance_rc=cov,
        gain=a,
        offset=b,
        rms_residual=math.sqrt(s2),
        noise_sigma=sigma,
        excess_frac=excess,
        iou=iou,
        ncc=ncc,
        iterations=st.it,
        R_body_to_camera=np.asarray(st.R, dtype=float),
    )


__all__ = ["background_sigma", "center_covariance", "finish_registration", "overlap"]
