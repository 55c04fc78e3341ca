r"""Model error of the whole-limb fit from its two polarities: the lit limb against the dark limb.

The whole-limb stage (:mod:`jaxlimb.pipeline.sphere.whole_limb`) fits one elliptical sigmoid to the lit limb (disc
brighter than the sky) and the dark limb (disc darker than a brighter background) together.  The two see
different profiles: a crescent brightening toward the limb, a plume or a glow beside it, a dark limb
softened by the sky's gradient.  A profile the sigmoid does not describe moves the fitted edge, and the
two polarities are moved differently -- the centre's pixel-noise covariance does not know it (on the
Cassini Enceladus frames the image's own dark-limb edges sit 0.7-1.1 px outside the fitted limb, against
-0.02 px on a render, ``benchmarks/cassini_enceladus.py``).

The split measures it: with the scale ``a`` held at the joint fit (so that a short lit arc does not trade
its centre for its radius), the centre is fitted on the lit pixels alone and on the dark pixels alone.
The joint fit is the lit limb's (its pixels are weighted by their contrast, 10-100x the dark limb's), and
on renders the dark limb is the unbiased one (a uniform dark disc: 0.006-0.06 px; a crescent whose
brightness ramps toward the limb: the lit edge moves 0.35 px toward the Sun, the dark one does not).  So
the split :math:`\Delta = c_{lit} - c_{dark}` estimates the joint centre's model error, and
:math:`\Delta\Delta^\top` is added to the centre covariance whenever both polarities are measured -- a
data-driven term, not a tuned constant.  Its noise (:math:`S = \Sigma_{lit} + \Sigma_{dark}`, the dark
fit's mostly) makes it conservative when the model is right; ``chi2`` :math:`= \Delta^\top S^{-1}\Delta`
is reported (> :data:`CHI2_MIN`: the polarities disagree beyond their noise).

The scale is split too: the dark limb fitted alone with its scale ``a`` free as well (:func:`dark_scale`).  The
joint scale is the lit limb's, and a crescent brightening toward the limb, a glow or a plume beside it move the lit
edge outward all along the arc: the range from it is short.  The dark limb is an occultation edge -- the disc
hiding a brighter background, a step blurred by the PSF, the sigmoid's own profile -- and its scale is the one the
range is taken from (:func:`jaxlimb.pipeline.sphere.predicted.predicted_center`).  On the two Cassini Enceladus
frames the lit limb's scale is 0.8 and 1.2 % larger than the dark limb's; the range from the dark limb is within
0.15 and 0.23 % of SPICE's, the joint one 0.96 % short (``benchmarks/real_frames.py``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import ConvergenceError
from ...models import ELLIPSE
from ..sigmoid import run_fit
from .whole_limb import binned_limb_steps, ellipse_distance

#: Fewest pixels of each polarity for the split.
MIN_PIXELS = 50
#: Chi-square (2 dof) of the split above which the polarities are reported as disagreeing (~ 2 sigma).
CHI2_MIN = 4.0


def pixel_polarity(img: np.ndarray, mask: np.ndarray | None, shape, dr: float, noise: float, coords: np.ndarray,
                   n_bins: int = 180, min_snr: float = 5.0) -> np.ndarray:
    """+1 (lit: disc brighter than the sky), -1 (dark) or 0 for each of ``coords``, from its angular bin's
    inner and outer levels on the annulus ``|d| <= dr`` about ``shape`` (as
    :func:`jaxlimb.pipeline.sphere.whole_limb.select_whole_limb` classifies the bins).

    Parameters
    ----------
    img : np.ndarray (rows, cols)
    mask : np.ndarray of bool or None
        ``True`` = measured pixel.
    shape : LimbShape
        The fitted limb ellipse.
    dr : float
        Annulus half-width (px).
    noise : float
        Image noise (DN).
    coords : np.ndarray (n, 2)
        Pixels ``(row, col)`` to classify.
    n_bins : int
        Angular bins about the ellipse.
    min_snr : float
        Smallest step, in noise sigmas, for a bin to have a polarity.

    Returns
    -------
    np.ndarray (n,)
        ``+1.0``, ``-1.0`` or ``0.0``.
    """
    _, _, _, _, c, good, _ = binned_limb_steps(img, mask, shape, dr, noise, n_bins, min_snr)
    pol = np.where(good, np.sign(np.nan_to_num(c)), 0.0)
    _, phi_p = ellipse_distance(shape, coords)
    b = np.minimum(((phi_p + math.pi) / (2 * math.pi) * n_bins).astype(np.int64), n_bins - 1)
    return pol[b]


def polarity_split(img: np.ndarray, mask: np.ndarray | None, res, shape, dr: float, noise: float, opt,
                   fixed: tuple[str, ...]) -> dict[str, Any] | None:
    r"""The split of the module docstring for the whole-limb fit ``res`` (a
    :class:`~jaxlimb.pipeline.stages.RefineResult`); ``None`` when a polarity has too few pixels.

    Parameters
    ----------
    img, mask, shape, dr, noise
        As :func:`pixel_polarity`.
    res : RefineResult
        The joint (whole-limb) ESF fit.
    opt : LocateOptions
    fixed : tuple of str
        Parameters held in the joint fit (``a`` is held as well).

    Returns
    -------
    dict or None
        Lit and dark centres ``(row, col)``, their pixel counts, ``delta_rc_px``, ``chi2``, ``disagree`` and
        ``model_error_cov_px2`` (:math:`\Delta\Delta^\top`, px^2).
    """
    pol = pixel_polarity(img, mask, shape, dr, noise, res.data.coords)
    held = tuple(dict.fromkeys(tuple(fixed) + ("a",)))
    out: dict[str, Any] = {}
    for name, s in (("lit", 1.0), ("dark", -1.0)):
        sel = pol == s
        if np.count_nonzero(sel) < MIN_PIXELS:
            return None
        f = run_fit(ELLIPSE, res.data.subset(sel), res.fit.params, opt, held)
        i = [list(f.free).index(n) for n in ("r0", "c0")]
        out[name] = (np.array([float(f.params.r0), float(f.params.c0)]), np.asarray(f.covariance)[np.ix_(i, i)],
                     int(np.count_nonzero(sel)))
    delta = out["lit"][0] - out["dark"][0]
    S = out["lit"][1] + out["dark"][1]
    chi2 = float(delta @ np.linalg.solve(S, delta))
    M = np.outer(delta, delta)
    return {"lit_center_rc": out["lit"][0].tolist(), "dark_center_rc": out["dark"][0].tolist(),
            "n_lit": out["lit"][2], "n_dark": out["dark"][2], "delta_rc_px": delta.tolist(), "chi2": chi2,
            "disagree": bool(chi2 > CHI2_MIN), "model_error_cov_px2": M.tolist(),
            **dark_scale(res, pol == -1.0, opt, fixed)}


def dark_scale(res, dark: np.ndarray, opt, fixed: tuple[str, ...]) -> dict[str, float]:
    """The dark limb's own scale (module docstring): the ESF refitted on the ``dark`` pixels with the centre and
    ``a`` free (the shape ``fixed`` held as in the joint fit); empty when that fit does not converge.

    Parameters
    ----------
    res : RefineResult
        The joint (whole-limb) ESF fit.
    dark : np.ndarray of bool (n,)
        Its dark-limb pixels.
    opt : LocateOptions
    fixed : tuple of str
        Parameters held in the joint fit.

    Returns
    -------
    dict
        ``joint_a_px``, ``dark_a_px`` and ``dark_sigma_a_px`` (the dark fit's pixel-noise sigma of ``a``).
    """
    try:
        f = run_fit(ELLIPSE, res.data.subset(dark), res.fit.params, opt, tuple(fixed))
    except ConvergenceError:
        return {}
    i = list(f.free).index("a")
    return {"joint_a_px": float(res.fit.params.a), "dark_a_px": float(f.params.a),
            "dark_sigma_a_px": float(np.sqrt(np.asarray(f.covariance)[i, i]))}


__all__ = ["CHI2_MIN", "MIN_PIXELS", "dark_scale", "pixel_polarity", "polarity_split"]
