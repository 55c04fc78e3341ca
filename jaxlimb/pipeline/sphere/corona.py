"""The Sun's limb in the extreme ultraviolet (an optically thin corona over an opaque disc,
:data:`~jaxlimb.models.corona.CORONA`): the test that chooses it (a disc whose azimuthal brightness peaks at its limb,
not at its centre), its fit on an annulus about a circle, and the disc strategy's edge stage built on that fit."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import LimbInputError
from ...fitting import AbstractLimbSolver, NormalLM, solver_from_name
from ...models.corona import CORONA, CoronaParams
from ..checks import check_center_in_field, check_size
from ..frame import min_diameter_px
from ..stages import AnnulusSelection, EdgeFit, Frame, LimbPixels
from .annulus import annulus_halfwidth
from .sun import SunLimbFit, disc_fit_result, fit_free_sigma, select_sun_annulus

_WHAT = "EUV corona limb"


def limb_brightened(img: np.ndarray, center_rc, radius_px: float) -> bool:
    """Whether the disc's azimuthal mean brightness (1 px rings about ``center_rc``, out to ``radius_px``) peaks
    nearer its limb than its centre.

    An opaque photosphere is brightest at its centre and darkens toward the limb; an optically thin corona seen
    over an opaque disc (the Sun in the EUV) is brightest at the limb, where the line of sight is longest
    (:mod:`jaxlimb.models.corona`).

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image; non-finite pixels are left out.
    center_rc : (float, float)
        Disc centre ``(row, col)`` (px).
    radius_px : float
        Limb radius (px).

    Returns
    -------
    bool
        ``True`` when the brightest ring lies beyond half the radius.
    """
    R = float(radius_px)
    coords, z = select_sun_annulus(img, center_rc, 0.5 * R, 0.5 * R)  # the disc's pixels, its bounding box only
    d = np.hypot(coords[:, 0] - center_rc[0], coords[:, 1] - center_rc[1])
    keep = d < R
    if not keep.any():
        return False
    return bool(int(np.argmax(_ring_means(d[keep], z[keep]))) > 0.5 * R)


def _ring_means(d: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The mean of ``z`` in each 1 px ring ``floor(d)`` (``d >= 0``); ``-inf`` for a ring without pixels."""
    ring = np.floor(d).astype(int)
    counts = np.bincount(ring)
    return np.where(counts > 0, np.bincount(ring, weights=z) / np.maximum(counts, 1), -np.inf)


def ring_radius(img: np.ndarray, center_rc, radius_px: float) -> float:
    """The middle of the brightest 1 px ring within ``radius_px -+ max(6, radius_px / 10)`` of ``center_rc``: the
    corona peaks just above the occulting limb, and a circle found on its fall-off (a threshold's outline, a
    sigmoid) lies a few of the corona's scale heights (each some tens of Mm, several per cent of the radius) outside.

    Parameters
    ----------
    img : np.ndarray (rows, cols)
        The image; non-finite pixels are left out.
    center_rc : (float, float)
        Disc centre ``(row, col)`` (px).
    radius_px : float
        The circle's radius (px).

    Returns
    -------
    float
        The ring's radius (px).
    """
    R = float(radius_px)
    h = min(max(6.0, 0.1 * R), 0.5 * R)
    coords, z = select_sun_annulus(img, center_rc, R, h)
    d = np.hypot(coords[:, 0] - center_rc[0], coords[:, 1] - center_rc[1])
    return R - h + float(np.argmax(_ring_means(d - (R - h), z))) + 0.5


def _initial(coords, z, center_rc, R: float, h: float, sigma0: float) -> CoronaParams:
    """The start: the corona's level the annulus's 95th percentile above its 2nd (the sky), the disc level the
    median inside the limb above the sky."""
    d = np.hypot(coords[:, 0] - center_rc[0], coords[:, 1] - center_rc[1])
    inner = z[d < R - 0.5 * h]
    if inner.size == 0:
        raise LimbInputError("the annulus holds no pixels inside the limb: widen `annulus_px`")
    sky = float(np.percentile(z, 2))
    return CoronaParams(float(center_rc[0]), float(center_rc[1]), R, float(sigma0), math.log(h / 3.0),
                        float(np.percentile(z, 95)) - sky, max(float(np.median(inner)) - sky, 0.0), sky)


def fit_corona(img, center_rc, radius_px: float, *, annulus_px: float | None = None,
               solver: AbstractLimbSolver | None = None, sigma0: float = 0.7, max_steps: int = 256) -> SunLimbFit:
    """Fit the EUV limb (:data:`~jaxlimb.models.corona.CORONA`) on an annulus around a circle, then once more on the
    annulus around the fitted circle.  The start's radius is the brightest ring near the circle given
    (:func:`ring_radius`).

    Parameters
    ----------
    img : 2-D image ``[row, col]``; non-finite pixels are ignored.
    center_rc, radius_px : the starting circle (within a few pixels of the limb).
    annulus_px : half-width of the annulus (px); default ``max(6, 0.04 radius_px)``, at most ``radius_px / 2``.
    solver : default :class:`~jaxlimb.fitting.NormalLM`.
    sigma0 : starting PSF sigma (px); a sigma below the pixel box's is held at 0
        (:func:`~jaxlimb.pipeline.sphere.sun.fit_free_sigma`).
    max_steps : iteration limit.

    Returns
    -------
    SunLimbFit
        ``params`` are :class:`~jaxlimb.models.corona.CoronaParams`; ``radius_px`` is the occulting radius.

    Raises
    ------
    LimbInputError
        No pixels inside the limb.
    ConvergenceError
        A fit did not converge or returned non-finite parameters.

    References
    ----------
    Chapman 1931, Proc. Phys. Soc. 43, 483 (the grazing column); Aschwanden 2005, Physics of the Solar Corona,
    sec. 3.1.
    """
    R = float(radius_px)
    if not (math.isfinite(R) and R > 0):
        raise LimbInputError(f"`radius_px` must be finite and > 0, got {radius_px!r}")
    h = min(float(annulus_px) if annulus_px is not None else max(6.0, 0.04 * R), 0.5 * R)
    solver = solver if solver is not None else NormalLM(coarse_stride=1)
    R = ring_radius(img, center_rc, R)
    coords, z = select_sun_annulus(img, center_rc, R, h)
    init = _initial(coords, z, center_rc, R, h, sigma0)
    first = disc_fit_result(fit_free_sigma(CORONA, coords, z, init, solver, (), max_steps), h, (coords, z), _WHAT)
    coords, z = select_sun_annulus(img, first.center_rc, first.radius_px, h)
    res = fit_free_sigma(CORONA, coords, z, first.params, solver, (), max_steps)
    return disc_fit_result(res, h, (coords, z), _WHAT)


@dataclass(frozen=True)
class RingPixels(LimbPixels):
    """The limb pixels of a disc brightest at its limb (:func:`ring_pixels`): its edge stage is the corona's limb
    (:func:`corona_edge`)."""


def ring_pixels(img: np.ndarray, cand) -> RingPixels:  # noqa: ANN001
    """The limb pixels of a disc brightest at its limb: the whole annulus about the front end's circle, every pixel
    kept.  The sigmoid's selection keeps the angular bins with a lit step across the annulus, and a ring over a darker
    disc has none (a disc cut by the frame's border leaves its annulus no bin).  The corona's fit
    (:func:`corona_edge`) selects its own annulus; these pixels are what the report and the saturation check see.

    Parameters
    ----------
    img : np.ndarray
        The image the fit sees (invalid pixels NaN).
    cand : LimbCandidates
        The front end's circle.

    Returns
    -------
    RingPixels
        All round (``direction=None``, ``half=pi``); the annulus's halves as its levels.
    """
    dr = annulus_halfwidth(cand.radius, cand.residual_rms)
    coords, z = select_sun_annulus(img, cand.center_rc, cand.radius, dr)
    d = np.hypot(coords[:, 0] - cand.center_rc[0], coords[:, 1] - cand.center_rc[1]) - cand.radius
    inner = float(np.median(z[d < 0])) if np.any(d < 0) else float(np.median(z))
    outer = float(np.median(z[d >= 0])) if np.any(d >= 0) else float(np.median(z))
    n = len(z)
    sel = AnnulusSelection(coords=coords, z=z, center_rc=tuple(cand.center_rc), radius=float(cand.radius), dr=dr,
                           direction=None, halfangle=math.pi, inner_level=inner, outer_level=outer,
                           inner_edge_mean=inner, outer_edge_mean=outer, n_bins_kept=0, n_bins=0,
                           pixel_inner=np.full(n, inner), pixel_outer=np.full(n, outer))
    return RingPixels(sel, dr, None, math.pi, None, 0.0)


def corona_edge(frame: Frame, img: np.ndarray, cand, pixels: LimbPixels) -> EdgeFit:  # noqa: ANN001
    """The edge stage of a disc brightest at its limb: the corona's limb itself (:func:`fit_corona` from the front
    end's circle), where a sigmoid would fit a ring over a darker disc (and, on the corona's fall-off alone, an edge
    whose outer level the frame may not reach).  Checks 1 (size) and 4 (centre in the field); Check 5's jump is
    reported but not limited: the fit starts at the brightest ring, not at the front end's circle (the outline of
    the corona at a threshold, a few scale heights out).

    Parameters
    ----------
    frame : Frame
    img : np.ndarray
        The image the fit sees (invalid pixels NaN).
    cand : LimbCandidates
        The front end's circle.
    pixels : LimbPixels
        The annulus about it (reported).

    Returns
    -------
    EdgeFit
        ``circ`` the corona's fit on its annulus (noise-only covariance), the full circle as its arc.
    """
    solver = None if frame.opt.solver == "lm" else solver_from_name(frame.opt.solver)
    sun = fit_corona(img, cand.center_rc, cand.radius, solver=solver)
    jump = math.hypot(sun.center_rc[0] - cand.center_rc[0], sun.center_rc[1] - cand.center_rc[1]) + abs(
        sun.radius_px - cand.radius)
    frame.mark("refine")
    check_size(sun.radius_px, frame.img.shape, min_diameter_px(frame), 360.0)
    check_center_in_field(sun.center_rc, sun.radius_px, frame.img.shape)
    return EdgeFit(sun.refine_result(), pixels, False, True, 360.0, jump, math.inf)


__all__ = ["RingPixels", "corona_edge", "fit_corona", "limb_brightened", "ring_pixels", "ring_radius"]
