r"""The fit of a few-pixel body: the blurred lit disc of :mod:`jaxlimb.models.small_disc` over a window of pixels
about the blob, its noise model and its covariance.

Passes.  (1) Unweighted, from the centre of brightness less the phase offset, the expected radius (or the blob's
second moment) and the blob's flux; the sample grid then re-centred on the estimate.  (2) Weighted by a noise model
estimated from pass 1's residuals, :math:`\mathrm{var}_i = s_0^2 + g\,m_i` with ``m_i`` the model's signal at pixel
``i`` above the sky (read noise and photon noise): ``s0`` from the residuals of the sky pixels (1.4826 MAD), ``g``
the least-squares slope of the squared residuals of the body's pixels on ``m`` (``>= 0``).  Without it the sky's
pixels, which outnumber the body's, set :math:`\hat\sigma` and a photon-noise-limited blob's centre sigma comes out
too small.

Radius and law.  The radius ``a`` and the law's weight ``L`` are free when the disc is resolved (expected radius at
least :data:`FREE_RADIUS_MIN_PX`) or when the hints give no size: ``L`` is then the surface's limb darkening as the
pixels show it, a nuisance parameter (held at the phase's lunar-Lambert value on a surface of another law it biases
the radius and the centre: ``benchmarks/small_bodies.py --law hapke``).  Else both are held, ``a`` at the expected
radius (camera, range, body radius) and ``L`` at the phase's value, and their uncertainties (the hints' fraction,
default :data:`~jaxlimb.pipeline.frame.DEFAULT_RADIUS_UNCERTAINTY`; :data:`~jaxlimb.pipeline.small.blob.LAW_SIGMA`)
are carried into the covariance as consider parameters:
:math:`\Delta C = s s^\top \sigma_a^2` with :math:`s = -(J_f^\top W J_f)^{-1} J_f^\top W j_a` the free
parameters' response to a change of ``a`` (and the same for ``L``): the phase offset of a crescent depends on the
law, which a few pixels do not measure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import ConvergenceError
from ...fitting import fit
from ...models import lunar_lambert_weight
from ...models.small_disc import (N_SUB, SMALL_DISC, SMALL_DISC_FIXED, WINDOW, SmallDiscParams, grid_half_extent,
                                  photocentre_offset, radiance_grid, small_disc_predict)
from ..profile.fit import profile_sun_direction
from ..stages import FitData, Frame, RefineResult
from .blob import LAW_SIGMA, BlobCandidates

#: Expected radius (px) from which the disc's radius is fitted (below it: held, a consider parameter).
FREE_RADIUS_MIN_PX = 3.0
#: Solver steps per pass.
MAX_STEPS = 200


@dataclass(frozen=True)
class SmallPixels:
    """The window of pixels the disc is fitted to: ``coords`` ``(n, 2)``, ``z``, the window's top-left pixel."""

    coords: np.ndarray
    z: np.ndarray
    win_rc: tuple[int, int]


def window_pixels(img: np.ndarray, valid: np.ndarray | None, peak) -> SmallPixels:
    """The valid pixels of the ``WINDOW x WINDOW`` window centred on ``peak``, moved inside the frame when the frame
    holds it (one pixel count: one compiled fit).

    Parameters
    ----------
    img : numpy.ndarray
        The image ``(rows, cols)`` (DN).
    valid : numpy.ndarray of bool or None
        Valid pixels (``None``: all).
    peak : tuple of int
        ``(row, col)`` of the blob's smoothed peak.

    Returns
    -------
    SmallPixels
        Pixel coordinates ``(n, 2)`` (px), their values (DN, float64) and the window's top-left pixel.
    """
    wr, wc = (int(peak[i]) - WINDOW // 2 for i in range(2))
    wr, wc = (max(0, min(w, n - WINDOW)) if n >= WINDOW else w for w, n in zip((wr, wc), img.shape))
    rr, cc = np.mgrid[wr: wr + WINDOW, wc: wc + WINDOW]
    ok = (rr >= 0) & (rr < img.shape[0]) & (cc >= 0) & (cc < img.shape[1])
    rr, cc = rr[ok], cc[ok]
    if valid is not None:
        keep = valid[rr, cc]
        rr, cc = rr[keep], cc[keep]
    return SmallPixels(np.stack([rr, cc], axis=1).astype(np.float64), img[rr, cc].astype(np.float64), (wr, wc))


def sun_geometry(frame: Frame, center_rc) -> tuple[float, float, float]:
    """``(sun_r, sun_c, phase)`` at ``center_rc`` from the hints (``(1, 0, 0)``: full phase when unknown).

    Parameters
    ----------
    frame : Frame
        Its hints give the Sun direction (and its camera the line of sight).
    center_rc : tuple of float
        Body centre ``(row, col)`` (px).

    Returns
    -------
    tuple of float
        Unit image direction ``(sun_r, sun_c)`` toward the Sun and the phase angle (rad).
    """
    if not frame.sun_known:
        return 1.0, 0.0, 0.0
    assert frame.hints is not None
    sun_rc = profile_sun_direction(frame.hints.sun_dir_camera, frame.cam, center_rc if frame.cam is not None else None)
    return float(sun_rc[0]), float(sun_rc[1]), float(frame.phase(center_rc))


def disc_at(cand: BlobCandidates, pix: SmallPixels, center_rc, a: float, sigma: float, sun) -> SmallDiscParams:
    """The disc of radius ``a`` at ``center_rc`` (its sample grid about it), its amplitude from the blob's flux.

    Parameters
    ----------
    cand : BlobCandidates
        The blob: its sky (``ymin``) and flux (``amp``).
    pix : SmallPixels
        The window (its top-left pixel).
    center_rc : tuple of float
        Disc centre ``(row, col)`` (px).
    a : float
        Apparent radius (px).
    sigma : float
        PSF sigma (px).
    sun : tuple of float
        ``(sun_r, sun_c, phase)``: unit image direction toward the Sun and phase (rad) (:func:`sun_geometry`).

    Returns
    -------
    SmallDiscParams
        The disc, its lunar-Lambert weight ``L`` from the phase.
    """
    L = lunar_lambert_weight(sun[2])
    p = SmallDiscParams(r0=float(center_rc[0]), c0=float(center_rc[1]), a=float(a), sigma=float(sigma), amp=1.0,
                        ymin=float(cand.sky), sun_r=sun[0], sun_c=sun[1], phase=sun[2], L=L,
                        win_r=float(pix.win_rc[0]), win_c=float(pix.win_rc[1]), grid_r=float(center_rc[0]),
                        grid_c=float(center_rc[1]), grid_h=2.0 * grid_half_extent(a) / N_SUB)
    unit = float(np.sum(np.asarray(radiance_grid(p)[2])))
    return p.replace(amp=float(cand.flux) / max(unit, 1e-300))


def regrid(p: SmallDiscParams) -> SmallDiscParams:
    """``p`` with its sample grid centred on its disc and sized for its radius.

    Parameters
    ----------
    p : SmallDiscParams

    Returns
    -------
    SmallDiscParams
        ``p`` with ``grid_r, grid_c`` at ``(r0, c0)`` and ``grid_h`` from
        :func:`~jaxlimb.models.small_disc.grid_half_extent` of ``a``.
    """
    return p.replace(grid_r=float(p.r0), grid_c=float(p.c0), grid_h=2.0 * grid_half_extent(float(p.a)) / N_SUB)


def offset_and_gradients(p: SmallDiscParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The disc's phase offset (:func:`~jaxlimb.models.small_disc.photocentre_offset`) and its change per px of radius
    and per unit of ``L`` (central differences).

    Parameters
    ----------
    p : SmallDiscParams
        The disc.

    Returns
    -------
    offset : numpy.ndarray
        Phase offset ``(d_row, d_col)`` (px).
    d_offset_da : numpy.ndarray
        Its change ``(2,)`` per px of radius.
    d_offset_dl : numpy.ndarray
        Its change ``(2,)`` (px) per unit of ``L``.
    """
    off = np.array(photocentre_offset(p))
    a, L = float(p.a), float(p.L)
    da = 0.01 * a
    g_a = (np.array(photocentre_offset(regrid(p.replace(a=a + da)))) -
           np.array(photocentre_offset(regrid(p.replace(a=a - da))))) / (2 * da)
    g_l = (np.array(photocentre_offset(p.replace(L=L + 0.05))) - np.array(photocentre_offset(p.replace(L=L - 0.05)))) / 0.1
    return off, g_a, g_l


def start(frame: Frame, cand: BlobCandidates, pix: SmallPixels) -> SmallDiscParams:
    """Pass 1's start (module docstring).

    Parameters
    ----------
    frame : Frame
        Its hints give the Sun direction and phase.
    cand : BlobCandidates
        The blob: centre of brightness, expected radius or second moment, flux, sky.
    pix : SmallPixels
        The window.

    Returns
    -------
    SmallDiscParams
        The disc at the centre of brightness less its phase offset, with the expected (or moment) radius and
        ``sigma = 0.8`` px.
    """
    sun = sun_geometry(frame, cand.centroid_rc)
    sigma0 = 0.8
    if cand.expected_radius_px is not None:
        a0 = float(cand.expected_radius_px)
    else:  # a uniform disc's variance per axis is a^2/4; the PSF and the pixel add theirs
        a0 = 2.0 * math.sqrt(max(cand.second_moment - sigma0 * sigma0 - 1.0 / 12.0, 0.25))
    p = disc_at(cand, pix, cand.centroid_rc, a0, sigma0, sun)
    off = photocentre_offset(p)
    return disc_at(cand, pix, (cand.centroid_rc[0] - off[0], cand.centroid_rc[1] - off[1]), a0, sigma0, sun)


def noise_weights(p: SmallDiscParams, pix: SmallPixels, free: tuple[str, ...]) -> tuple[np.ndarray, dict[str, float]]:
    """``1 / sqrt(s0^2 + g m)`` (module docstring) and ``{s0, g, n_body}``.

    The squared residuals are divided by ``1 - h_ii``, ``h_ii`` the leverage of pixel ``i`` in pass 1's unweighted fit
    of the ``free`` parameters (MacKinnon & White 1985, HC2): the fit absorbs part of the noise of the few body
    pixels that fix it (at a radius of 1 px, a few tens of pixels for 5 parameters), and their raw residuals
    underestimate its photon noise.

    Parameters
    ----------
    p : SmallDiscParams
        Pass 1's disc.
    pix : SmallPixels
        The window.
    free : tuple of str
        Pass 1's free parameters.

    Returns
    -------
    weights : numpy.ndarray
        Per-pixel weight ``(n,)`` (1/DN).
    noise : dict
        ``s0`` (DN) and ``g`` (DN per DN of signal) of the noise model.
    """
    m = np.asarray(small_disc_predict(p, pix.coords)) - float(p.ymin)
    J = np.asarray(SMALL_DISC.jacobian(p, pix.coords))[:, [SmallDiscParams.field_names().index(n) for n in free]]
    lev = np.einsum("ij,ij->i", J, np.linalg.lstsq(J.T @ J, J.T, rcond=None)[0].T)
    r = (pix.z - (m + float(p.ymin))) / np.sqrt(np.clip(1.0 - lev, 1e-3, None))
    top = float(np.max(m)) if m.size else 0.0
    sky = m < 0.01 * top
    rs = r[sky] if np.count_nonzero(sky) >= 20 else r
    s0 = max(1.4826 * float(np.median(np.abs(rs - np.median(rs)))), 1e-12)
    body = m > 0.1 * top
    g = 0.0
    if np.count_nonzero(body) >= 3:
        mb = m[body]
        g = max(float(np.sum((r[body] ** 2 - s0 * s0) * mb) / np.sum(mb * mb)), 0.0)
    return 1.0 / np.sqrt(s0 * s0 + g * np.maximum(m, 0.0)), {"s0": s0, "g": g, "n_body": int(np.count_nonzero(body))}


def consider_terms(res, pix: SmallPixels, weights: np.ndarray, sigmas: dict[str, float]) -> np.ndarray:
    """The covariance (over the fit's free parameters) of held parameters' uncertainties (module docstring).

    Parameters
    ----------
    res : LimbFit
        The weighted fit: its parameters and free set.
    pix : SmallPixels
        The window.
    weights : numpy.ndarray
        Per-pixel weight ``(n,)`` of the fit (1/DN).
    sigmas : dict
        Parameter name -> 1-sigma of a held parameter (``a`` in px, ``L``); free ones and zeros are skipped.

    Returns
    -------
    numpy.ndarray
        The added covariance ``(q, q)`` over the free parameters, in their order.
    """
    p = res.params
    names = SmallDiscParams.field_names()
    J = np.asarray(SMALL_DISC.jacobian(p, pix.coords)) * weights[:, None]
    free = [names.index(n) for n in res.free]
    Jf = J[:, free]
    N = Jf.T @ Jf
    out = np.zeros((len(free), len(free)))
    for name, s in sigmas.items():
        if name in res.free or s <= 0:
            continue
        sk = -np.linalg.solve(N, Jf.T @ J[:, names.index(name)])
        out += np.outer(sk, sk) * s * s
    return out


def check_in_window(res, pix: SmallPixels) -> None:
    """A disc fit that measured its blob: the centre inside the window of pixels it fitted and the normal matrix of its
    free parameters of full rank; else :class:`~jaxlimb.errors.ConvergenceError` (the solver's steps can carry the
    centre far off a faint blob while its tolerance is met: nothing there for the fit to see).

    Parameters
    ----------
    res : LimbFit
        The weighted fit.
    pix : SmallPixels
        The window.

    Raises
    ------
    ConvergenceError
        The centre outside the window, or free parameters the data do not fix.
    """
    lo, hi = pix.coords.min(axis=0), pix.coords.max(axis=0)
    r0, c0 = float(res.params.r0), float(res.params.c0)
    if not (lo[0] <= r0 <= hi[0] and lo[1] <= c0 <= hi[1]):
        raise ConvergenceError(f"the few-pixel disc fit left its window: centre ({r0:.4g}, {c0:.4g}) outside rows "
                               f"{lo[0]:g}-{hi[0]:g}, cols {lo[1]:g}-{hi[1]:g}")
    C = np.asarray(res.covariance, float)
    if not np.all(np.isfinite(C)) or np.linalg.matrix_rank(C) < C.shape[0]:
        raise ConvergenceError("the few-pixel disc fit has free parameters the window's pixels do not fix")


def fit_small_disc(frame: Frame, cand: BlobCandidates, pix: SmallPixels) -> tuple[RefineResult, dict]:
    """The passes of the module docstring: the :class:`~jaxlimb.pipeline.stages.RefineResult` (its covariance with the
    consider terms; the noise-only one kept) and what to report.

    Parameters
    ----------
    frame : Frame
        The prepared inputs.
    cand : BlobCandidates
        The blob (:func:`~jaxlimb.pipeline.small.blob.find_blob`).
    pix : SmallPixels
        The window (:func:`window_pixels`).

    Returns
    -------
    result : RefineResult
        The weighted disc fit with the consider covariance.
    info : dict
        The noise model, whether the radius (and ``L``) was free, the radius's fractional 1-sigma and ``L``'s
        (``None`` when fitted).

    Raises
    ------
    ConvergenceError
        A weighted pass does not converge, or its answer is not a measurement (:func:`check_in_window`).
    """
    a_free = cand.expected_radius_px is None or cand.expected_radius_px >= FREE_RADIUS_MIN_PX
    held = () if a_free else ("a", "L")  # a run-time mask: one compiled fit whether they are held or not
    fixed = SMALL_DISC_FIXED + held
    p = start(frame, cand, pix)
    res = fit(SMALL_DISC, pix.coords, pix.z, p, fixed=SMALL_DISC_FIXED, held=held, max_steps=MAX_STEPS, throw=False)
    p = regrid(res.params)
    w, noise = noise_weights(p, pix, tuple(n for n in SmallDiscParams.field_names() if n not in fixed))
    for _ in range(2):  # the grid follows the estimate
        res = fit(SMALL_DISC, pix.coords, pix.z, p, fixed=SMALL_DISC_FIXED, held=held, weights=w, max_steps=MAX_STEPS,
                  throw=True)
        moved = math.hypot(float(res.params.r0) - float(p.grid_r), float(res.params.c0) - float(p.grid_c))
        p = regrid(res.params)
        if moved < 0.05 * float(p.grid_h) * N_SUB / 2:
            break
    check_in_window(res, pix)
    a = float(res.params.a)
    u = cand.radius_uncertainty
    C_fit = np.asarray(res.covariance)
    C = C_fit + consider_terms(res, pix, w, {"a": u * a, "L": LAW_SIGMA})
    data = FitData(pix.coords, pix.z, None, 0.0, 1.0)  # (the weights are the noise model's: in ``res``, not here)
    rr = RefineResult(res, data, 0, tuple(fixed)).with_covariance(C, noise_covariance=C_fit)
    return rr, {"noise_model": noise, "radius_free": a_free, "radius_uncertainty_frac": u,
                "law_sigma_L": None if a_free else LAW_SIGMA}


__all__ = ["FREE_RADIUS_MIN_PX", "SmallPixels", "check_in_window", "disc_at", "fit_small_disc",
           "offset_and_gradients", "regrid", "start", "sun_geometry", "window_pixels"]
