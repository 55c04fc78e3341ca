r"""Check "dark limb": a limb fitted on the lit side must agree with the dark limb where the dark limb is visible.

A crescent of a body seen at high phase against a brighter background (the Cassini frames of Enceladus:
E-ring and plume light behind the night side) shows its *whole* limb: the lit arc (disc brighter than the
sky) and the dark arc (disc darker than the sky).  The lit-limb stages of :func:`jaxlimb.pipeline.locate`
(front end, annulus on the lit side, circular sigmoid; Aerospace 2015 §4-6) fit a circle to the lit arc
only.  On a short arc the circle's radius and centre trade off (Christian & Robinson's short-arc
geometry), and a limb that is not a circle -- a triaxial body (Enceladus' 256 x 247 x 245 km image to a
limb ~4 % out of round) -- biases both: on a Cassini frame, a 304.6 px circle ~15 px outside the dark disc
opposite the crescent, with a centre sigma of 0.1 px.

The check searches the edge of largest |gradient| along the normals of the fitted circle
(:func:`jaxlimb.imaging.predicted.limb_edges`, either polarity, masked pixels left out) and takes the
edges where the disc is darker than the sky.  When at least :data:`MIN_DARK_BINS` such bins are found,
the sky is brighter than the disc across them by :data:`MIN_DARK_CONTRAST_SIGMA` noise sigmas (median; a
black sky's JPEG blocks and quantisation steps are not a limb) and their median radial offset from the fitted circle exceeds :data:`MAX_DARK_OFFSET_PX` (or
:data:`MAX_DARK_OFFSET_FRAC` of the radius), the lit-limb circle is not the body's limb: a typed failure
(:class:`~jaxlimb.errors.DarkLimbInconsistentError`, exit 3) instead of a confident wrong answer.  The
remedy is the prediction (``--kernels``: camera, range and the body's orientation), with which the whole
limb, lit and dark, is fitted with the body's own shape (:mod:`jaxlimb.pipeline.sphere.whole_limb`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import DarkLimbInconsistentError
from ...imaging.crop import estimate_noise
from ...imaging.gradient import bilinear
from ...imaging.predicted import LimbShape, limb_edges
from ..frame import frame_mask

#: Fewest dark-limb bins (of 360) for the check to apply (a disc on a black sky has none).
MIN_DARK_BINS = 20
#: Smallest median sky-minus-disc step across the dark-limb edges, in noise sigmas, for them to be a limb
#: (JPEG blocks and quantisation on a black sky give ~0.1-0.6 sigma; Enceladus' dark limb 3.9, a 3 DN render 3.0).
MIN_DARK_CONTRAST_SIGMA = 2.5
#: Largest accepted median offset (px) of the dark limb from the fitted circle ...
MAX_DARK_OFFSET_PX = 3.0
#: ... or this fraction of the radius, whichever is larger.
MAX_DARK_OFFSET_FRAC = 0.01


def dark_limb_offset(image: np.ndarray, center_rc, radius_px: float, mask: np.ndarray | None = None,
                     search_px: float | None = None) -> dict[str, Any]:
    """Edges along the normals of the circle ``(center_rc, radius_px)``: the number of dark-limb bins (disc
    darker than the sky) and their median signed radial offset from the circle (px; < 0 inside).

    Parameters
    ----------
    image : np.ndarray (rows, cols)
    center_rc : (float, float)
        Fitted circle centre ``(row, col)`` (px).
    radius_px : float
    mask : np.ndarray of bool, optional
        ``True`` = measured pixel.
    search_px : float, optional
        Half-length of the search along each normal (px); default ``0.1 radius`` clipped to ``[10, 30]``.

    Returns
    -------
    dict
        ``n_bins``, ``n_lit_bins``, ``search_px``, ``median_offset_px`` and ``median_contrast_dn`` (sky minus disc,
        ``None`` without dark bins), ``noise_dn``.
    """
    r = float(radius_px)
    s = float(search_px) if search_px is not None else float(np.clip(0.1 * r, 10.0, 30.0))
    c = (float(center_rc[0]), float(center_rc[1]))
    img = np.asarray(image, dtype=np.float64)
    noise = estimate_noise(img)
    pts, step, ok = limb_edges(img, LimbShape(c, r, 1.0, 0.0), mask=mask, search_px=s, noise=noise)
    dark = ok & (step < 0)
    n = int(np.count_nonzero(dark))
    off = np.hypot(pts[dark, 0] - c[0], pts[dark, 1] - c[1]) - r
    return {"n_bins": n, "n_lit_bins": int(np.count_nonzero(ok & (step > 0))), "search_px": s,
            "median_offset_px": float(np.median(off)) if n else None,
            "median_contrast_dn": _median_contrast(img, pts[dark], c) if n else None, "noise_dn": noise}


def _median_contrast(img: np.ndarray, pts: np.ndarray, center: tuple[float, float]) -> float:
    """Median over the edges ``pts`` of the sky level minus the disc level (DN): the mean of the image
    3-6 px outside minus 3-6 px inside each edge along the radius."""
    u = pts - np.asarray(center)
    u /= np.maximum(np.linalg.norm(u, axis=1), 1e-12)[:, None]
    side = [np.mean([bilinear(img, *(pts + sgn * d * u).T) for d in (3.0, 4.0, 5.0, 6.0)], axis=0) for sgn in (1, -1)]
    return float(np.median(side[0] - side[1]))


def check_dark_limb(image: np.ndarray, center_rc, radius_px: float, mask: np.ndarray | None = None) -> dict[str, Any]:
    """The check of the module docstring; returns :func:`dark_limb_offset`'s numbers when it passes.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
    center_rc : (float, float)
        Fitted circle centre ``(row, col)`` (px).
    radius_px : float
    mask : np.ndarray of bool, optional
        ``True`` = measured pixel.

    Returns
    -------
    dict
        :func:`dark_limb_offset`'s numbers with ``limit_px`` and ``is_limb`` (enough contrasted dark bins).

    Raises
    ------
    DarkLimbInconsistentError
        The visible dark limb lies off the fitted circle.
    """
    d = dark_limb_offset(image, center_rc, radius_px, mask)
    limit = max(MAX_DARK_OFFSET_PX, MAX_DARK_OFFSET_FRAC * float(radius_px))
    d["limit_px"] = limit
    contrast = d["median_contrast_dn"]
    d["is_limb"] = bool(d["n_bins"] >= MIN_DARK_BINS and contrast is not None
                        and contrast >= MIN_DARK_CONTRAST_SIGMA * max(d["noise_dn"], 1e-12))
    if d["is_limb"] and abs(d["median_offset_px"]) > limit:
        where = "inside" if d["median_offset_px"] < 0 else "outside"
        raise DarkLimbInconsistentError(
            f"the dark limb ({d['n_bins']} of 360 directions where the disc is darker than the sky) lies "
            f"{abs(d['median_offset_px']):.1f} px {where} the circle fitted to the lit limb (radius {radius_px:.1f} px; "
            f"limit {limit:.1f} px): the lit arc alone does not fix this limb (a crescent, or a body not round); "
            "give the prediction (--kernels: camera, range, orientation) to fit the whole limb")
    return d


def check_measurement(frame: Any, meas: Any) -> Any:
    """Stage "checks" of a sphere: :func:`check_dark_limb` on the measured circle; the numbers in ``extras``.

    Parameters
    ----------
    frame : Frame
    meas : LimbMeasurement
        Unchecked when it has no finite radius (an ellipse).

    Returns
    -------
    LimbMeasurement
        ``meas``, its ``extras["dark_limb"]`` set.
    """

    if meas.radius_px is None or not math.isfinite(meas.radius_px):
        return meas
    meas.extras["dark_limb"] = check_dark_limb(frame.img, meas.center_rc, meas.radius_px, frame_mask(frame))
    return meas


__all__ = ["MAX_DARK_OFFSET_FRAC", "MAX_DARK_OFFSET_PX", "MIN_DARK_BINS", "MIN_DARK_CONTRAST_SIGMA", "check_dark_limb", "check_measurement",
           "dark_limb_offset"]
