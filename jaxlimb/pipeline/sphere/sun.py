"""Fit of the limb-darkened disc of a self-luminous star (the Sun) on an annulus about a circle, the disc
strategy's profile refit.  The model (:data:`~jaxlimb.models.LIMB_DARKENED`, the quadratic limb-darkening law blurred
by a Gaussian PSF, and its Jacobian) lives in :mod:`jaxlimb.models`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import ConvergenceError, LimbInputError
from ...fitting import AbstractLimbSolver, fit, LimbFit, NormalLM
from ...models import LIMB_DARKENED, LimbDarkenedParams, limb_darkened_intensity, limb_darkening
from ...models.limb_darkened import SUN_FIXED, U1_DEFAULT, U2_DEFAULT
from ..stages import FitData, RefineResult

#: Below this PSF sigma (px) :func:`fit_limb_darkened` refits with ``sigma`` held at 0.
SIGMA_FLOOR = 0.03
_FIRST_STEPS = 16
"""Steps per chunk of the sigma-free fit (:func:`fit_free_sigma`): on data sharper than the pixel box
sigma is below :data:`SIGMA_FLOOR` within 12-16 steps (SDO/HMI), and every chunk is the same program."""


@dataclass(frozen=True)
class SunLimbFit:
    """Result of :func:`fit_limb_darkened`.

    Attributes
    ----------
    center_rc : disc centre ``(row, col)`` (px).
    radius_px : limb radius ``a`` (px): the edge of the photosphere's disc.
    covariance : ``(3, 3)`` covariance of ``(r0, c0, a)`` (px^2), from the fit's
        :math:`\\hat\\sigma^2 (J^\\top J)^{-1}` (pixel noise taken as white).
    params : the estimated :class:`LimbDarkenedParams` or :class:`~jaxlimb.models.corona.CoronaParams`
        (``sigma`` reported as ``|sigma|``).
    fit : the underlying :class:`~jaxlimb.fitting.LimbFit` (full covariance over its ``free``).
    n_pixels : pixels used (finite, inside the annulus).
    annulus_px : the annulus half-width used.
    pixels : the annulus's pixels ``(coords (n, 2), values (n,))`` the fit used.
    """

    center_rc: tuple[float, float]
    radius_px: float
    covariance: np.ndarray
    params: Any
    fit: LimbFit
    n_pixels: int
    annulus_px: float
    pixels: tuple[np.ndarray, np.ndarray]

    def refine_result(self) -> RefineResult:
        """The fit as the pipeline's profile-refit value: its annulus's pixels (unit weights, DN), the parameters it
        did not fit held.

        Returns
        -------
        RefineResult
            Its covariance the fit's own (noise only).
        """
        coords, z = self.pixels
        held = tuple(n for n in type(self.params).field_names() if n not in self.fit.free)
        return RefineResult(self.fit, FitData(coords, z, None, 0.0, 1.0), 0, held)


def select_sun_annulus(img: np.ndarray, center_rc, radius_px: float, annulus_px: float):
    """Finite pixels with ``|d - radius_px| <= annulus_px`` (full 360 deg) about ``center_rc``.

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        Non-finite pixels (masked ones set to NaN) are left out.
    center_rc : (float, float)
        Disc centre ``(row, col)`` (px).
    radius_px, annulus_px : float
        Limb radius and annulus half-width (px).

    Returns
    -------
    coords : np.ndarray (n, 2)
        Pixels ``(row, col)``.
    z : np.ndarray (n,)
        Their values.
    """
    img = np.asarray(img, dtype=float)
    r0, c0 = (float(v) for v in center_rc)
    R, h = float(radius_px), float(annulus_px)
    rlo, rhi = max(0, int(math.floor(r0 - R - h))), min(img.shape[0], int(math.ceil(r0 + R + h)) + 1)
    clo, chi = max(0, int(math.floor(c0 - R - h))), min(img.shape[1], int(math.ceil(c0 + R + h)) + 1)
    rr, cc = np.mgrid[rlo:rhi, clo:chi]
    d = np.hypot(rr - r0, cc - c0)
    z = img[rlo:rhi, clo:chi]
    keep = (np.abs(d - R) <= h) & np.isfinite(z)
    return np.stack([rr[keep], cc[keep]], axis=1).astype(float), z[keep]


def _initial(coords, z, center_rc, R, h, u1, u2, sigma0) -> LimbDarkenedParams:
    d = np.hypot(coords[:, 0] - center_rc[0], coords[:, 1] - center_rc[1])
    out, inn = z[d > R + min(0.5 * h, 1.5)], z[d < R - 0.5 * h]
    if inn.size == 0:
        raise LimbInputError("the annulus holds no pixels inside the limb: widen `annulus_px`")
    # sky: pixels outside the limb, or (FITS with off-disc NaN close to the limb) the darkest ones
    ymin = float(np.median(out)) if out.size else float(np.min(z))
    mu = math.sqrt(max(1.0 - ((R - 0.75 * h) / R) ** 2, 0.0))
    lim = 1.0 - u1 * (1.0 - mu) - u2 * (1.0 - mu) ** 2
    amp = (float(np.median(inn)) - ymin) / max(lim, 0.05)
    return LimbDarkenedParams(float(center_rc[0]), float(center_rc[1]), float(R), float(sigma0), amp, ymin,
                              float(u1), float(u2))


def fit_limb_darkened(img, center_rc, radius_px: float, *, annulus_px: float | None = None,
                      solver: AbstractLimbSolver | None = None, fixed: tuple[str, ...] = SUN_FIXED,
                      u1: float = U1_DEFAULT, u2: float = U2_DEFAULT, sigma0: float = 0.7,
                      max_steps: int = 256) -> SunLimbFit:
    """Fit the limb-darkened disc model (module docstring) on an annulus around a circle.

    Parameters
    ----------
    img : 2-D image ``[row, col]``; non-finite pixels are ignored (FITS off-disc NaN).
    center_rc, radius_px : the starting circle (e.g. :func:`jaxlimb.pipeline.locate`'s;
        within ~1 px of the limb).
    annulus_px : half-width of the annulus (px); default ``max(6, 0.04 radius_px)``,
        at most ``radius_px / 2``.
    solver : default :class:`~jaxlimb.fitting.NormalLM`.
    fixed : parameters held at their starting values (default ``("u2",)``).  If ``sigma`` is
        free and the fit drives it below :data:`SIGMA_FLOOR` (or does not converge), the fit is
        repeated with ``sigma = 0`` held: the image is as sharp as the pixel-box model allows
        (the 512 px HMI PNG is: its limb wants ``sigma_e ~ 0.19 px < sqrt(1/12)``).
    u1, u2 : starting (or held) limb-darkening coefficients.
    sigma0 : starting PSF sigma (px).
    max_steps : iteration limit.

    Returns
    -------
    SunLimbFit

    Raises
    ------
    LimbInputError
        No pixels inside the limb, or too few pixels.
    ConvergenceError
        The fit did not converge or returned non-finite parameters.

    References
    ----------
    Kopal 1950 (quadratic law); Pierce & Slaughter 1977, Sol. Phys. 51, 25 and Neckel &
    Labs 1994, Sol. Phys. 153, 91 (measured solar limb darkening); Cox (ed.) 2000, Allen's
    Astrophysical Quantities, sec. 14.7 (quadratic coefficients).
    """
    R = float(radius_px)
    if not (math.isfinite(R) and R > 0):
        raise LimbInputError(f"`radius_px` must be finite and > 0, got {radius_px!r}")
    h = float(annulus_px) if annulus_px is not None else max(6.0, 0.04 * R)
    h = min(h, 0.5 * R)
    coords, z = select_sun_annulus(img, center_rc, R, h)
    init = _initial(coords, z, center_rc, R, h, u1, u2, sigma0)
    solver = solver if solver is not None else NormalLM(coarse_stride=1)
    fixed = tuple(fixed)
    if "sigma" in fixed:
        res = fit(LIMB_DARKENED, coords, z, init, solver, fixed=fixed, max_steps=max_steps, throw=False)
    else:
        res = fit_free_sigma(LIMB_DARKENED, coords, z, init, solver, fixed, max_steps)
    return disc_fit_result(res, h, (coords, z), "limb-darkened disc")


def disc_fit_result(res: LimbFit, annulus_px: float, pixels: tuple[np.ndarray, np.ndarray], what: str) -> SunLimbFit:
    """A disc fit as a :class:`SunLimbFit`: its parameters with ``sigma`` as ``|sigma|`` (the models depend on its
    square) and the covariance of ``(r0, c0, a)``.

    Parameters
    ----------
    res : LimbFit
        The fit (parameters with ``r0, c0, a, sigma``).
    annulus_px : float
        The annulus half-width it used.
    pixels : tuple
        Its pixels ``(coords, values)``.
    what : str
        The model's name, for the messages.

    Returns
    -------
    SunLimbFit

    Raises
    ------
    ConvergenceError
        The fit did not converge or returned non-finite parameters.
    """
    if not bool(res.converged):
        raise ConvergenceError(f"{what} fit ({res.solver}) did not converge: {res.message}")
    p = res.params
    vals = np.asarray(p.to_vector())
    if not np.all(np.isfinite(vals)):
        raise ConvergenceError(f"{what} fit returned non-finite parameters {vals.tolist()}")
    p = p.replace(sigma=abs(float(p.sigma)))
    idx = [res.free.index(n) for n in ("r0", "c0", "a") if n in res.free]
    cov = np.asarray(res.covariance)[np.ix_(idx, idx)]
    return SunLimbFit(center_rc=(float(p.r0), float(p.c0)), radius_px=float(p.a), covariance=cov, params=p, fit=res,
                      n_pixels=int(res.n_pixels), annulus_px=float(annulus_px), pixels=pixels)


def fit_free_sigma(model, coords, z, init, solver, fixed: tuple[str, ...], max_steps: int):  # noqa: ANN001, ANN201
    """The fit of a disc ``model`` (parameters with ``sigma``) with the PSF sigma free, run in chunks of
    :data:`_FIRST_STEPS` steps.

    When the data are as sharp as (or sharper than) the pixel box, sigma -> 0, where its Jacobian column
    vanishes (sigma enters as sigma^2) and the iteration crawls: below :data:`SIGMA_FLOOR` (or below 0.1
    px while not converged) the fit is redone with sigma held at 0.  Sigma is held by
    :func:`~jaxlimb.fitting.fit`'s run-time mask (``held``), so the chunks and the refit are one compiled
    program: a process loads one fit core per model from the compilation cache, not two.

    Parameters
    ----------
    model : LimbModel
        :data:`LIMB_DARKENED` or :data:`~jaxlimb.models.corona.CORONA`.
    coords, z : np.ndarray
        The annulus's pixels ``(n, 2)`` and values ``(n,)``.
    init : LimbParams
        The start.
    solver : AbstractLimbSolver
    fixed : tuple of str
        Parameters held at their start.
    max_steps : int
        Iteration limit.

    Returns
    -------
    LimbFit
        The fit (not checked: :func:`disc_fit_result` checks it).
    """
    chunk = min(max_steps, _FIRST_STEPS)
    res = fit(model, coords, z, init, solver, fixed=fixed, max_steps=chunk, throw=False, held=())
    done = int(res.n_steps)
    while True:
        sigma = abs(float(res.params.sigma))
        if sigma < SIGMA_FLOOR or (not bool(res.converged) and sigma < 0.1):
            return fit(model, coords, z, init.replace(sigma=0.0), solver, fixed=fixed, held=("sigma",),
                       max_steps=max_steps, throw=False)
        if bool(res.converged) or done >= max_steps:
            return res
        res = fit(model, coords, z, res.params, solver, fixed=fixed, max_steps=chunk, throw=False, held=())
        done += int(res.n_steps)


__all__ = ["LIMB_DARKENED", "SUN_FIXED", "U1_DEFAULT", "U2_DEFAULT", "LimbDarkenedParams", "SunLimbFit",
           "disc_fit_result", "fit_free_sigma", "fit_limb_darkened", "limb_darkened_intensity", "limb_darkening",
           "select_sun_annulus"]
