"""Figure features: area, centre, attitude vector, Hu moments (Eq. 10-14 of Wu et al.).

Coordinates: moments use ``x = col`` and ``y = row`` (the OpenCV convention); the
image frame (x right, y down) has the same handedness as the camera frame
(+x toward +col, +y toward +row), so a rotation of the body about the boresight
is a rotation by the same angle in the (x, y) image plane.  Swapping x and y is
a reflection and flips the sign of Hu's 7th moment.

Two sources of raw moments ``m_pq`` (p + q <= 3) are supported:

* a binary mask: pixel-centre sums (``cv2.moments(..., binaryImage=True)``);
* a closed polygon (the traced contour of a template): exact polygon moments by
  Green's theorem -- Eq. (14) of Wu et al. is the ``m00`` case; this is the
  contour-based fast moment algorithm the paper cites (Liu and Zhang).

Guards against the known failure modes of Hu-moment matching
(see :mod:`.matching` for how they are used):

* **near-zero moments**: ``h3..h7`` of near-symmetric figures are tiny and
  dominated by pixel noise; raw differences of them match anything and plain
  ``log|h|`` explodes near zero.  :func:`log_hu` maps each moment to
  ``sign(h) * log10(1 + |h| / floor)`` -- logarithmic compression above the
  floor, linear (and continuous through zero) below it.
* **mirror images**: the sign of ``h7`` is kept (a mirrored figure has the
  opposite ``h7``; the view from the antipode of a viewpoint is the mirror
  image of its figure);
* **unstable attitude vector**: besides the paper's farthest point, the
  second-moment orientation (:func:`orientation`) and several distinct far
  points (:func:`far_point_candidates`) are exposed so that the rotation can be
  chosen by contour agreement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

# index of m_pq in the raw-moment vector
_RAW = ("m00", "m10", "m01", "m20", "m11", "m02", "m30", "m21", "m12", "m03")

#: Default floors of :func:`log_hu` (roughly the size of each moment for a
#: slightly irregular 100-px figure; below them a moment is treated linearly).
HU_FLOORS = np.array([1e-3, 1e-5, 1e-6, 1e-7, 1e-12, 1e-9, 1e-12])


def raw_moments_mask(mask: np.ndarray) -> np.ndarray:
    """Raw moments ``m_pq`` (p+q <= 3) of a binary mask, ``x = col``, ``y = row``.

    Parameters
    ----------
    mask : np.ndarray (rows, cols)
        Binary figure (non-zero inside).

    Returns
    -------
    np.ndarray (10,)
        ``m00, m10, m01, m20, m11, m02, m30, m21, m12, m03`` (pixel-centre sums).
    """
    m = cv2.moments(np.ascontiguousarray(mask, dtype=np.uint8), binaryImage=True)
    return np.array([m[k] for k in _RAW])


def raw_moments_polygon(xy: np.ndarray) -> np.ndarray:
    """Exact raw moments ``m_pq`` (p+q <= 3) of a closed simple polygon in ``(x, y)``.

    Green's theorem per edge ``i -> i+1`` with ``a_i = x_i y_{i+1} - x_{i+1} y_i``
    (Eq. 14 of Wu et al. is ``m00 = sum(a)/2`` up to the orientation sign).
    The result is for a counter-clockwise orientation in the (x, y) plane, i.e. the
    sign is normalised so that ``m00 > 0``.

    Parameters
    ----------
    xy : np.ndarray (n, 2)
        Polygon vertices ``(x=col, y=row)``, px, either orientation.

    Returns
    -------
    np.ndarray (10,)
        ``m00, m10, m01, m20, m11, m02, m30, m21, m12, m03``.
    """
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    x0, y0 = p[:, 0], p[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    a = x0 * y1 - x1 * y0
    m00 = a.sum() / 2.0
    m10 = (a * (x0 + x1)).sum() / 6.0
    m01 = (a * (y0 + y1)).sum() / 6.0
    m20 = (a * (x0 * x0 + x0 * x1 + x1 * x1)).sum() / 12.0
    m02 = (a * (y0 * y0 + y0 * y1 + y1 * y1)).sum() / 12.0
    m11 = (a * (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0)).sum() / 24.0
    m30 = (a * (x0**3 + x0**2 * x1 + x0 * x1**2 + x1**3)).sum() / 20.0
    m03 = (a * (y0**3 + y0**2 * y1 + y0 * y1**2 + y1**3)).sum() / 20.0
    m21 = (a * (x0**2 * (3 * y0 + y1) + 2 * x0 * x1 * (y0 + y1) + x1**2 * (y0 + 3 * y1))).sum() / 60.0
    m12 = (a * (y0**2 * (3 * x0 + x1) + 2 * y0 * y1 * (x0 + x1) + y1**2 * (x0 + 3 * x1))).sum() / 60.0
    m = np.array([m00, m10, m01, m20, m11, m02, m30, m21, m12, m03])
    return m if m00 >= 0 else -m


def central_moments(raw: np.ndarray) -> tuple[float, float, float, np.ndarray]:
    """Area, centroid and central moments from raw moments.

    Parameters
    ----------
    raw : np.ndarray (10,)
        Raw moments in the order of :func:`raw_moments_mask`.

    Returns
    -------
    area : float
        ``m00`` (px^2).
    xbar, ybar : float
        Centroid ``(x=col, y=row)``, px.
    mu : np.ndarray (7,)
        ``mu20, mu11, mu02, mu30, mu21, mu12, mu03``.

    Raises
    ------
    ValueError
        The area is not positive.
    """
    m00, m10, m01, m20, m11, m02, m30, m21, m12, m03 = raw
    if not m00 > 0:
        raise ValueError(f"figure area must be > 0, got m00={m00!r}")
    xb, yb = m10 / m00, m01 / m00
    mu20 = m20 - xb * m10
    mu11 = m11 - xb * m01
    mu02 = m02 - yb * m01
    mu30 = m30 - 3 * xb * m20 + 2 * xb * xb * m10
    mu21 = m21 - 2 * xb * m11 - yb * m20 + 2 * xb * xb * m01
    mu12 = m12 - 2 * yb * m11 - xb * m02 + 2 * yb * yb * m10
    mu03 = m03 - 3 * yb * m02 + 2 * yb * yb * m01
    return float(m00), float(xb), float(yb), np.array([mu20, mu11, mu02, mu30, mu21, mu12, mu03])


def hu_from_central(area: float, mu: np.ndarray) -> np.ndarray:
    """Hu's seven invariants, Eq. (10)-(11), from normalised central moments, Eq. (13).

    ``eta_pq = mu_pq / area^((p+q+2)/2)`` (the binary figure, grey value 1 inside).

    Parameters
    ----------
    area : float
        ``m00`` (px^2).
    mu : np.ndarray (7,)
        Central moments of :func:`central_moments`.

    Returns
    -------
    np.ndarray (7,)
        ``h1 .. h7``; invariant to translation, scale and rotation, ``h7`` changes sign under reflection.
    """
    mu20, mu11, mu02, mu30, mu21, mu12, mu03 = mu
    n2 = area**2.0
    n3 = area**2.5
    e20, e11, e02 = mu20 / n2, mu11 / n2, mu02 / n2
    e30, e21, e12, e03 = mu30 / n3, mu21 / n3, mu12 / n3, mu03 / n3
    a, b = e30 + e12, e21 + e03
    c, d = e30 - 3 * e12, 3 * e21 - e03
    h1 = e20 + e02
    h2 = (e20 - e02) ** 2 + 4 * e11**2
    h3 = c**2 + d**2
    h4 = a**2 + b**2
    h5 = c * a * (a**2 - 3 * b**2) + d * b * (3 * a**2 - b**2)
    h6 = (e20 - e02) * (a**2 - b**2) + 4 * e11 * a * b
    h7 = d * a * (a**2 - 3 * b**2) - c * b * (3 * a**2 - b**2)
    return np.array([h1, h2, h3, h4, h5, h6, h7])


def log_hu(hu: np.ndarray, floors: np.ndarray = HU_FLOORS) -> np.ndarray:
    """Guarded, log-scaled Hu moments ``sign(h) log10(1 + |h|/floor)`` (keeps h7's sign).

    Parameters
    ----------
    hu : np.ndarray (..., 7)
        Hu moments.
    floors : np.ndarray (7,)
        Magnitude below which each moment is scaled linearly (module docstring).

    Returns
    -------
    np.ndarray (..., 7)
    """
    h = np.asarray(hu, dtype=float)
    return np.sign(h) * np.log10(1.0 + np.abs(h) / floors)


def orientation(mu: np.ndarray) -> float:
    """Second-moment orientation ``0.5 atan2(2 mu11, mu20 - mu02)`` (rad, x=col, y=row).

    Defined modulo pi; meaningless when ``mu20 ~ mu02`` and ``mu11 ~ 0``.

    Parameters
    ----------
    mu : np.ndarray (7,)
        Central moments (the first three are used).

    Returns
    -------
    float
        Angle of the major axis from +x toward +y, rad.
    """
    return 0.5 * math.atan2(2.0 * mu[1], mu[0] - mu[2])


def elongation(mu: np.ndarray) -> float:
    """``(l1 - l2) / (l1 + l2)`` of the second-moment matrix: 0 for isotropic figures.

    Parameters
    ----------
    mu : np.ndarray (7,)
        Central moments (the first three are used).

    Returns
    -------
    float
        In [0, 1].
    """
    mu20, mu11, mu02 = mu[:3]
    return float(math.hypot(mu20 - mu02, 2 * mu11) / max(mu20 + mu02, 1e-300))


def resample_closed(xy: np.ndarray, n: int) -> np.ndarray:
    """Resample a closed polyline to ``n`` points equally spaced in arc length.

    Parameters
    ----------
    xy : np.ndarray (m, 2)
        Closed polyline (the last point joins the first).
    n : int
        Points returned.

    Returns
    -------
    np.ndarray (n, 2)
        Starting at ``xy[0]``; ``n`` copies of it for a polyline of zero length.
    """
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    q = np.vstack([p, p[:1]])
    seg = np.hypot(*np.diff(q, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return np.repeat(p[:1], n, axis=0)
    t = np.arange(n) * (s[-1] / n)
    return np.stack([np.interp(t, s, q[:, 0]), np.interp(t, s, q[:, 1])], axis=1)


def far_point_candidates(
    contour_xy: np.ndarray, center_xy: np.ndarray, n: int = 3, min_sep_rad: float = math.radians(20.0)
) -> np.ndarray:
    """Up to ``n`` contour points farthest from the centre, at least ``min_sep_rad`` apart in angle.

    The first one is the paper's attitude point ``F`` (Eq. 18); the others are
    alternatives for near-symmetric figures.

    Parameters
    ----------
    contour_xy : np.ndarray (m, 2)
        Contour points ``(x, y)``.
    center_xy : np.ndarray (2,)
        Figure centre ``C`` ``(x, y)``.
    n : int
        Most points returned.
    min_sep_rad : float
        Smallest angle about ``C`` between two returned points, rad.

    Returns
    -------
    np.ndarray (k, 2)
        Vectors ``F - C``, farthest first, ``k <= n``.
    """
    d = np.asarray(contour_xy, dtype=float) - center_xy
    r = np.hypot(d[:, 0], d[:, 1])
    ang = np.arctan2(d[:, 1], d[:, 0])
    alive = np.ones(r.shape, dtype=bool)
    out: list[np.ndarray] = []
    for _ in range(n):
        if not alive.any():
            break
        i = int(np.argmax(np.where(alive, r, -np.inf)))
        out.append(d[i])
        sep = np.abs(np.remainder(ang - ang[i] + math.pi, 2 * math.pi) - math.pi)
        alive &= sep >= min_sep_rad
    return np.array(out)


@dataclass(frozen=True)
class FigureFeatures:
    """Features of one figure (Sec. 3.3 of Wu et al.).

    Attributes
    ----------
    area
        ``S`` (px^2), Eq. (14).
    center_rc
        Centre point ``C`` (row, col).
    hu
        Hu moments ``h1..h7``, Eq. (10)-(13).
    orientation
        Second-moment orientation (rad, modulo pi) in the (x=col, y=row) plane.
    attitude_xy
        Attitude vector ``CF`` to the farthest contour point, ``(x=col, y=row)``.
    contour_xy
        Outer contour relative to ``C``, resampled to equal arc length, ``(n, 2)`` ``(x, y)``.
    """

    area: float
    center_rc: np.ndarray
    hu: np.ndarray
    orientation: float
    elongation: float
    attitude_xy: np.ndarray
    contour_xy: np.ndarray


def features_from_raw(raw: np.ndarray, contour_xy: np.ndarray, n_contour: int = 128) -> FigureFeatures:
    """Assemble :class:`FigureFeatures` from raw moments and the outer contour ``(x, y)``.

    Parameters
    ----------
    raw : np.ndarray (10,)
        Raw moments of the figure.
    contour_xy : np.ndarray (m, 2)
        Its outer contour ``(x=col, y=row)``.
    n_contour : int
        Points of the stored, resampled contour.

    Returns
    -------
    FigureFeatures
    """
    area, xb, yb, mu = central_moments(raw)
    c = np.array([xb, yb])
    cont = resample_closed(contour_xy, n_contour) - c
    far = far_point_candidates(np.asarray(contour_xy, float).reshape(-1, 2), c, n=1)[0]
    return FigureFeatures(
        area=area,
        center_rc=np.array([yb, xb]),
        hu=hu_from_central(area, mu),
        orientation=orientation(mu),
        elongation=elongation(mu),
        attitude_xy=far,
        contour_xy=cont,
    )


def largest_contour(contours: list[np.ndarray]) -> np.ndarray:
    """The external contour of largest area, as ``(n, 2)`` float ``(x, y)``.

    Parameters
    ----------
    contours : list of np.ndarray
        Contours as returned by ``cv2.findContours``.

    Returns
    -------
    np.ndarray (n, 2)

    Raises
    ------
    ValueError
        No contour.
    """
    if not contours:
        raise ValueError("no contour")
    polys = [np.asarray(c, dtype=float).reshape(-1, 2) for c in contours]
    areas = [abs(float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(np.roll(p[:, 0], -1), p[:, 1]))) for p in polys]
    return polys[int(np.argmax(areas))]


def features_from_contours(contours: list[np.ndarray], n_contour: int = 128) -> FigureFeatures:
    """Features of a template figure from its external contour(s) (polygon moments).

    Parameters
    ----------
    contours : list of np.ndarray
        External contours ``(x, y)``; moments are summed over all of them (pieces of one figure).
    n_contour : int
        Points of the stored contour (the largest one, resampled).

    Returns
    -------
    FigureFeatures
    """
    raw = np.zeros(10)
    for cnt in contours:
        xy = cnt.reshape(-1, 2).astype(float)
        if xy.shape[0] >= 3:
            raw += raw_moments_polygon(xy)
    return features_from_raw(raw, largest_contour(contours), n_contour)


def features_from_mask(mask: np.ndarray, n_contour: int = 128) -> FigureFeatures:
    """Features of an observed binary figure (pixel-count moments, traced contour).

    Parameters
    ----------
    mask : np.ndarray (rows, cols)
        Binary figure.
    n_contour : int
        Points of the stored contour.

    Returns
    -------
    FigureFeatures
    """
    m8 = np.ascontiguousarray(mask, dtype=np.uint8)
    contours, _ = cv2.findContours(m8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return features_from_raw(raw_moments_mask(m8), largest_contour(list(contours)), n_contour)


__all__ = [
    "HU_FLOORS",
    "FigureFeatures",
    "central_moments",
    "elongation",
    "far_point_candidates",
    "features_from_contours",
    "features_from_mask",
    "features_from_raw",
    "hu_from_central",
    "largest_contour",
    "log_hu",
    "orientation",
    "raw_moments_mask",
    "raw_moments_polygon",
    "resample_closed",
]
