"""The outline front end of a self-luminous disc (a star): its limb all round is the outline of its bright region.

A star has no lit side and no terminator, so the boundary of its region above Otsu's threshold (:func:`otsu_region`:
the largest component, holes filled) is a circle about its centre wherever it is the disc's edge: a sunspot, an
active region or a filament inside the disc does not move it, and the corona of an EUV image widens it evenly.  The
outline points (``cv2.findContours``) on the frame's border or next to invalid pixels are not the disc's edge and are
dropped; the circle is RANSAC's (:func:`~jaxlimb.conics.ransac.ransac_circle`, Taubin on its inliers), which at least
half the points must agree with: a region that is not the disc (part of an EUV limb ring above the threshold) is
refused.  The front ends made for sunlit bodies look for a lit step and a lit side, and on an EUV disc -- a bright
ring on a darker disc -- find parts of the ring.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..conics.ransac import RansacOptions, ransac_circle
from ..errors import NoBodyError, TooManyOutliersError
from .candidates import LimbCandidates
from .crop import nearest_fill

#: Fewest outline points that define the circle.
MIN_OUTLINE_POINTS = 12
#: Least fraction of the outline's points on its circle (RANSAC, Check 3): a disc's outline is mostly its limb.
MIN_ON_CIRCLE = 0.5


def otsu_region(image: np.ndarray) -> np.ndarray:
    """The largest connected region above Otsu's threshold of the lightly smoothed image (``cv2.threshold`` on the
    grey levels between the 0.1 and 99.9 percentiles, in 8 bits), holes filled: ``uint8`` 0/1.

    Otsu's threshold splits the histogram in two classes of least variance within them (Otsu 1979, IEEE Trans.
    SMC 9, 62), whatever the brightest few pixels are (Eq. 10's threshold, a fraction of the peak, lies above an EUV
    disc's limb when an active region outshines it).

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        The grey image (finite).

    Returns
    -------
    np.ndarray of uint8
        1 on the region, 0 elsewhere.

    Raises
    ------
    NoBodyError
        A flat frame, or nothing above the threshold.
    """
    sm = cv2.GaussianBlur(image, (0, 0), 1.0)
    lo, hi = np.percentile(sm, [0.1, 99.9])
    if not hi > lo:
        raise NoBodyError("no body in the image: the frame is flat")
    grey = np.clip((sm - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)
    _, binary = cv2.threshold(grey, 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    if n <= 1:
        raise NoBodyError("no body in the image: nothing above Otsu's threshold")
    comp = (labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    cnts, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(comp)
    cv2.drawContours(filled, cnts, -1, 1, thickness=cv2.FILLED)
    return filled


def _outline_points(region: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """The region's outer boundary ``(row, col)``, without the points on the frame's border or next to invalid
    pixels."""
    cnts, _ = cv2.findContours(region, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    xy = max(cnts, key=len)[:, 0, :]
    h, w = region.shape
    keep = (xy[:, 0] > 0) & (xy[:, 1] > 0) & (xy[:, 0] < w - 1) & (xy[:, 1] < h - 1)
    if mask is not None:
        bad = cv2.dilate((~np.asarray(mask, bool)).astype(np.uint8), np.ones((5, 5), np.uint8))
        keep &= bad[xy[:, 1], xy[:, 0]] == 0
    return xy[keep][:, ::-1].astype(float)


def outline_front_end(image: np.ndarray, mask: np.ndarray | None = None) -> LimbCandidates:
    """The limb candidates of a self-luminous disc from its region's outline (module docstring).

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        The grey image.
    mask : np.ndarray of bool, optional
        ``True`` where the pixel was measured.

    Returns
    -------
    LimbCandidates
        The outline points kept, their circle, no lit side (``lit_direction=None``, ``lit_halfangle=pi``),
        ``front_end="outline"``.

    Raises
    ------
    NoBodyError
        A flat frame, or nothing above the threshold.
    TooManyOutliersError
        Fewer than :data:`MIN_OUTLINE_POINTS` outline points are the disc's edge, or less than :data:`MIN_ON_CIRCLE`
        of them lie on one circle.
    """
    img = nearest_fill(np.asarray(image, dtype=float), mask)
    pts = _outline_points(otsu_region(img), mask)
    if len(pts) < MIN_OUTLINE_POINTS:
        raise TooManyOutliersError(f"the disc's outline has {len(pts)} points off the frame's border and invalid "
                                   f"pixels, fewer than {MIN_OUTLINE_POINTS}")
    res = ransac_circle(pts, RansacOptions(min_inlier_fraction=MIN_ON_CIRCLE))
    if not res:
        raise TooManyOutliersError(f"the disc's outline is not a circle: {res.reason}")
    pts, fit = pts[res.inliers], res.circle
    return LimbCandidates(points_rc=pts, center_rc=(float(fit.center_rc[0]), float(fit.center_rc[1])),
                          radius=float(fit.radius), residual_rms=float(fit.rms), lit_direction=None,
                          lit_halfangle=math.pi, front_end="outline", info={"n_outline": int(len(pts))})


__all__ = ["MIN_ON_CIRCLE", "MIN_OUTLINE_POINTS", "otsu_region", "outline_front_end"]
