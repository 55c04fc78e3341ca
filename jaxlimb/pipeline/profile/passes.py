"""The physical limb profile's fit passes (the sphere's image shape iterated with a camera), its start's PSF from a
sigmoid's steepness, a frame's clip level, and the accepted range of the fitted lunar-Lambert weight ``L``.  The
model (:data:`~jaxlimb.models.LIMB_PROFILE`, its Jacobian) lives in :mod:`jaxlimb.models`."""

from __future__ import annotations

import math

import numpy as np

from ...fitting import NormalLM
from ...geometry.sphere_image import sphere_from_circle_fit, sphere_from_ellipse_center
from ...models import LIMB_PROFILE, LimbModel, LimbProfileParams, PROFILE_FIXED
from ...models.lunar_lambert import PHYSICAL_L
from ..sigmoid import LOGISTIC_TO_GAUSS, run_fit
from ..stages import FitData, Frame


#: The profile's parameters held in its fit: the Sun's image direction, the phase and ``1/f`` (from the hints and the
#: camera); the lunar-Lambert weight ``L`` is estimated, from McEwen's ``L(phase)``: it adapts the profile to Lambert
#: (0) ... Lommel-Seeliger (1) limbs; its change across the disc with the phase angle, ``L_slope``, is McEwen's.
PROFILE_HELD = tuple(n for n in PROFILE_FIXED if n != "L")


def l_band(fit) -> tuple[float, float]:
    """The accepted range of ``L``: :data:`~jaxlimb.models.lunar_lambert.PHYSICAL_L` widened by 3 sigma of ``L`` when
    ``L`` was estimated.

    Parameters
    ----------
    fit : LimbFit
        A fit of :data:`~jaxlimb.models.LIMB_PROFILE` (or one of its widened forms).

    Returns
    -------
    tuple of float
        ``(L_min, L_max)``; ``(-inf, inf)`` when ``L`` was held.
    """
    if "L" not in fit.free:
        return (-math.inf, math.inf)
    i = list(fit.free).index("L")
    s = float(np.sqrt(max(float(np.asarray(fit.covariance)[i, i]), 0.0)))
    return (PHYSICAL_L[0] - 3.0 * s, PHYSICAL_L[1] + 3.0 * s)


def in_band(L: tuple[float, float], band: tuple[float, float]) -> bool:
    """Whether a profile is lunar-Lambert-like: its one-albedo ``L`` inside :func:`l_band`, or its ``L`` under the
    albedo field inside :data:`~jaxlimb.models.lunar_lambert.PHYSICAL_L` itself.  An albedo that darkens toward the
    limb drives the one-albedo ``L`` out of the band (a spotted Lambert Earth: -0.12 to -0.23) and the field brings it
    back; the refit is a second model tried after the first failed, so it is held to the physical range without the
    band's allowance for noise (a flat disc's ``L``, 2.0-2.3 as fitted, is 1.4-1.6 under the field: inside a band
    widened by a poorly determined ``L``, not a surface's).

    Parameters
    ----------
    L : tuple of float
        ``L`` as fitted (one albedo) and under the albedo field.
    band : tuple of float
        :func:`l_band` of the one-albedo fit.

    Returns
    -------
    bool
    """
    return band[0] <= L[0] <= band[1] or PHYSICAL_L[0] <= L[1] <= PHYSICAL_L[1]


def l_rejection(fit, refit) -> dict | None:
    """``extras["profile_rejected"]`` of a profile that is not lunar-Lambert-like (:func:`in_band`), else ``None``:
    the test both body strategies ask of their profile.

    Parameters
    ----------
    fit : LimbFit
        The one-albedo profile fit (its :func:`l_band`).
    refit : LimbFit
        Its refit under the albedo field (``fit`` itself when there is none).

    Returns
    -------
    dict or None
        ``{"model", "L", "L_under_field", "allowed_L"}`` when rejected.
    """
    band, L = l_band(fit), (float(fit.params.L), float(refit.params.L))
    if in_band(L, band):
        return None
    return {"model": "lunar-lambert", "L": L[0], "L_under_field": L[1], "allowed_L": list(band)}


__all__ = ["in_band", "l_band", "l_rejection"]


def saturation_level(img: np.ndarray) -> float | None:
    """The clip level of ``img`` if it has one: its maximum when >= 20 pixels sit exactly on it (noise never makes a
    plateau; clipping, including 12-bit data in 16-bit words, does).

    Parameters
    ----------
    img : np.ndarray
        The image.

    Returns
    -------
    float or None
        The clip level (DN), or ``None``.
    """
    m = float(np.max(img))
    return m if np.count_nonzero(img == m) >= 20 else None


def gaussian_sigma_of_k(k: float) -> float:
    """The PSF sigma (px, pixel box removed) of a blurred edge whose logistic steepness is ``k``:
    ``sqrt((LOGISTIC_TO_GAUSS / k)^2 - 1/12)``, at least 0.3 px.

    Parameters
    ----------
    k : float
        The sigmoid's steepness (px^-1).

    Returns
    -------
    float
        The Gaussian sigma (px).
    """
    s_e = LOGISTIC_TO_GAUSS / max(float(k), 1e-6)
    return math.sqrt(max(s_e * s_e - 1.0 / 12.0, 0.09))


def profile_passes(frame: Frame, data: FitData, start: LimbProfileParams, center, radius, fixed, solver,
                    model: LimbModel = LIMB_PROFILE):
    """The profile fit.  With a camera, the sphere's ellipse shape is held fixed and iterated.  The shape
    (``a - b`` ~ 5 px at the corner of the default imager for a 210 px Moon) changes by ~0.006 px per px
    of centre shift, so a second pass is run only when the shape at the fitted centre differs from the
    one fitted by more than 1e-3 px anywhere on the limb (:func:`shape_change_px`); it starts at the answer,
    without coarse phase.

    Parameters
    ----------
    frame : Frame
        The frame (camera, options).
    data : FitData
        Pixels ``(row, col)`` (ideal with a distorted camera) and values.
    start : LimbProfileParams
        The start.
    center, radius : tuple of float, float or None
        The circle (px) the sphere's shape starts from; ``None``: from ``start``.
    fixed : tuple of str
        Parameters held.
    solver : solver or None
        The first pass's solver (``None``: the options').
    model : LimbModel
        The profile model.

    Returns
    -------
    fit : LimbFit
        The last pass's fit.
    sphere : SphereImage or None
        The sphere's image at the fitted centre (``None`` without a camera).
    """
    opt = frame.opt
    if not frame.use_camera:
        return run_fit(model, data, start, opt, fixed, solver), None
    f, pp = frame.cam.focal_px, frame.cam.principal_point_rc
    q = start
    if center is not None:
        sph = sphere_from_circle_fit(f, pp, center, radius)
        q = start.replace(a=sph.a, theta=sph.angle_rad, rho=sph.rho)
    res = sph = None
    for i in range(2):
        s_i = solver if (i == 0 or solver is None) else NormalLM(rtol=0.0, atol=1e-5, coarse_stride=1)
        res = run_fit(model, data, q, opt, fixed, s_i)
        q = res.params
        sph = sphere_from_ellipse_center(f, pp, (float(q.r0), float(q.c0)), float(q.a))
        if shape_change_px(q, sph) < 1e-3:
            break
        q = q.replace(theta=float(sph.angle_rad), rho=float(sph.rho))
    return res, sph


def shape_change_px(q: LimbProfileParams, sph) -> float:
    """Largest radial change (px) of the limb ellipse of ``q`` if its axis ratio and orientation were those of
    ``sph`` (same ``a``): ``|d(a - b)| + (a - b) |d theta|``.

    Parameters
    ----------
    q : LimbProfileParams
        The fitted profile.
    sph : SphereImage
        The sphere's image at the fitted centre.

    Returns
    -------
    float
        The change (px).
    """
    a = float(q.a)
    dab = abs(a * (1.0 - float(q.rho)) - a * (1.0 - float(sph.rho)))
    dth = abs(math.remainder(float(q.theta) - float(sph.angle_rad), math.pi))
    return dab + a * abs(1.0 - float(sph.rho)) * dth
