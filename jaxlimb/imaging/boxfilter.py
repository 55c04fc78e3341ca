r"""Box-based outlier identification, §4.2 of the Aerospace 2015 paper (Fig. 7).

For each candidate edge pixel ``p`` (one of the N strongest gradients) a
``s x s`` box of the gradient image is analysed:

1. *Eigen-ratio test*: the inertia tensor of the gradient "mass" in the box has
   eigenvalues :math:`\lambda_{min} \le \lambda_{max}`; a true edge is a line of
   bright gradient, so :math:`\lambda_{min}/\lambda_{max} <` ``eigen_ratio_max`` (0.3).
   The eigenvector of the smallest moment of inertia (the largest spread) is the
   edge direction :math:`\hat t`, the other one the edge normal :math:`\hat n`.
2. *Edge-end test* (the pixels on the continuous line of Fig. 7): the gradients
   at :math:`p \pm h \hat t` (``h = s // 2``) are comparable,
   :math:`g_{min}/g_{max} >` ``end_ratio_min`` (0.6).
3. *Far-pixel tests* (the "D"/"U" pixels of Fig. 7, farthest from the edge line):
   at :math:`p \pm h \hat n` the gradient is small,
   :math:`\max(g) <` ``far_gradient_max`` :math:`\times\, g(p)`, and the grey
   tones differ (one is sky, one is body),
   :math:`I_{min}/I_{max} <` ``far_grey_ratio_max`` (0.3).

Decisions (the paper is silent on these):

* The paper chooses the D or U corner pixels according to
  :math:`\gamma \bmod \pi \lessgtr \pi/2`; we sample exactly along
  :math:`\pm h \hat t` and :math:`\pm h \hat n` (nearest pixel), the continuous
  version of the same rule.
* Gradient "mass" is ``max(g - w0 g(p), 0)`` with ``w0 = weight_floor`` (0.2):
  without a floor, the noise gradient of the ~s^2 background pixels adds an
  isotropic spread that defeats the eigen-ratio test at moderate SNR.
* Grey tones are measured above the background level (``background``) so that a
  sky offset does not break the ratio test.
* "Small" far gradient: below 0.5 g(p) (threshold missing in the paper).  It is
  skipped for ``h < 3`` (a box of 3 or 5 px is within one blur width of the edge).
* Validity mask (``valid``, :mod:`jaxlimb.imaging.formats`): invalid pixels carry no gradient mass,
  and a candidate whose edge-end or far pixel is invalid is rejected -- a masked pixel is neither
  limb nor background, so the tests cannot be made there.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError


#: The box's edge test (§4.2, §6 of the Aerospace 2015 paper): largest ``lambda_min / lambda_max`` (paper: 0.3) ...
EIGEN_RATIO_MAX = 0.3
#: ... smallest gradient ratio of the two edge-line ends (paper: 0.6) ...
END_RATIO_MIN = 0.6
#: ... largest grey-tone ratio of the two far pixels (paper: 0.3) ...
FAR_GREY_RATIO_MAX = 0.3
#: ... largest far-pixel gradient as a fraction of the centre's (decision: 0.5) ...
FAR_GRADIENT_MAX = 0.5
#: ... and the fraction of the centre gradient subtracted from the box's gradient mass (decision: 0.2).
WEIGHT_FLOOR = 0.2


def _box_ends(samp, G0, I0, g0, h, t, nrm, background):  # type: ignore[no-untyped-def]
    """The box's end and far-side samples (§4.2, Fig. 7): gradient at the two ends along the edge direction ``t``
    (``end_ratio``), gradient and grey level at the two far sides along the normal ``nrm`` (``far_grad``,
    ``far_grey_ratio``) and the two background-subtracted far grey levels."""
    (t_r, t_c), (n_r, n_c) = t, nrm
    ge1 = samp(G0, h * t_r, h * t_c, True)
    ge2 = samp(G0, -h * t_r, -h * t_c, True)
    end_ratio = np.minimum(ge1, ge2) / np.maximum(np.maximum(ge1, ge2), 1e-300)
    gf1 = samp(G0, h * n_r, h * n_c, True)
    gf2 = samp(G0, -h * n_r, -h * n_c, True)
    far_grad = np.maximum(gf1, gf2) / np.maximum(g0, 1e-300)
    i1 = np.maximum(samp(I0, h * n_r, h * n_c, False) - background, 0.0)
    i2 = np.maximum(samp(I0, -h * n_r, -h * n_c, False) - background, 0.0)
    grey_ratio = np.minimum(i1, i2) / np.maximum(np.maximum(i1, i2), 1e-300)
    return end_ratio, far_grad, grey_ratio, i1, i2


def box_filter(
    gradient: np.ndarray, image: np.ndarray, points_rc: np.ndarray, box_size: int, *, background: float = 0.0,
    valid: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Apply the box-based outlier filter to integer candidate pixels (vectorised).

    Parameters
    ----------
    gradient, image
        Gradient magnitude and grey image of the same shape.
    points_rc
        ``(n, 2)`` integer pixel positions ``(row, col)`` in those arrays.
    box_size
        Odd box side ``s >= 3``.
    background
        Sky level subtracted from the grey tones of the far-pixel test.
    valid
        Optional validity mask of the same shape (``True`` = measured pixel; module docstring).

    Returns
    -------
    keep : ``(n,)`` bool mask of accepted pixels.
    diag : dict of per-point arrays: ``eigen_ratio``, ``end_ratio``,
        ``far_grad``, ``far_grey_ratio``, ``normal_rc`` ``(n, 2)``.
    """
    s = int(box_size)
    if s < 3 or s % 2 == 0:
        raise ConfigError(f"box_size must be an odd integer >= 3, got {box_size!r}")
    h = s // 2
    P = np.asarray(points_rc, dtype=np.int64)
    n = P.shape[0]
    if n == 0:
        return np.zeros(0, bool), {}
    G0 = np.asarray(gradient)  # gathered values are converted to float64 below
    I0 = np.asarray(image)
    V = None if valid is None else _valid_mask(valid, G0.shape)
    pr, pc = P[:, 0], P[:, 1]
    patch = _gather_boxes(G0, pr, pc, h, V)
    g0 = G0[pr, pc].astype(np.float64)
    w = np.maximum(patch - WEIGHT_FLOOR * g0[:, None, None], 0.0)
    ratio, t_r, t_c = _edge_direction(w, h)
    n_r, n_c = -t_c, t_r
    samp = _box_sampler(pr, pc, h, G0.shape)
    end_ratio, far_grad, grey_ratio, i1, i2 = _box_ends(samp, G0, I0, g0, h, (t_r, t_c), (n_r, n_c), background)
    keep = _passes_thresholds(ratio, end_ratio, grey_ratio, far_grad, g0, h)
    if V is not None:
        for dr_, dc_ in ((t_r, t_c), (-t_r, -t_c), (n_r, n_c), (-n_r, -n_c)):
            keep &= samp(V, h * dr_, h * dc_, False) > 0.5
        keep &= V[pr, pc]
    # normal oriented from bright to dark (outward from the body)
    sign = np.where(i1 >= i2, -1.0, 1.0)
    diag = {
        "eigen_ratio": ratio,
        "end_ratio": end_ratio,
        "far_grad": far_grad,
        "far_grey_ratio": grey_ratio,
        "normal_rc": np.stack([sign * n_r, sign * n_c], axis=1),
    }
    return keep, diag


def _valid_mask(valid: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``valid`` as a boolean mask, checked to have the gradient's ``shape``."""
    V = np.asarray(valid, bool)
    if V.shape != shape:
        raise ConfigError(f"valid mask shape {V.shape} does not match the gradient shape {shape}")
    return V


def _passes_thresholds(ratio: np.ndarray, end_ratio: np.ndarray, grey_ratio: np.ndarray, far_grad: np.ndarray,
                       g0: np.ndarray, h: int) -> np.ndarray:
    """The points whose box tests pass their thresholds (the far-gradient test for boxes of half-side >= 3) and
    whose gradient is positive."""
    keep = (ratio < EIGEN_RATIO_MAX) & (end_ratio > END_RATIO_MIN) & (grey_ratio < FAR_GREY_RATIO_MAX)
    if h >= 3:
        keep &= far_grad < FAR_GRADIENT_MAX
    keep &= g0 > 0
    return keep


def _gather_boxes(G0: np.ndarray, pr: np.ndarray, pc: np.ndarray, h: int, V: np.ndarray | None) -> np.ndarray:
    """The ``(n, s, s)`` gradient boxes around the points (float64), by clipped indices instead of padding
    the whole array: the gradient outside the array (or at an invalid pixel) counts as 0."""
    R, C = G0.shape
    off = np.arange(-h, h + 1)
    rows = pr[:, None] + off[None, :]
    cols = pc[:, None] + off[None, :]
    vr = (rows >= 0) & (rows < R)
    vc = (cols >= 0) & (cols < C)
    rows_c = np.clip(rows, 0, R - 1)
    cols_c = np.clip(cols, 0, C - 1)
    inb = vr[:, :, None] & vc[:, None, :]
    if V is not None:
        inb = inb & V[rows_c[:, :, None], cols_c[:, None, :]]
    return G0[rows_c[:, :, None], cols_c[:, None, :]].astype(np.float64) * inb


def _edge_direction(w: np.ndarray, h: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalue ratio ``lambda_min / lambda_max`` of the weighted second moments of each box (§4.2; the
    inertia tensor has the same ratio) and the edge direction (unit eigenvector of ``lambda_max``,
    ``(row, col)`` components)."""
    o = np.arange(-h, h + 1).astype(np.float64)
    wr = w.sum(2)  # (n, s): mass per row offset
    wc = w.sum(1)  # (n, s): mass per col offset
    W = wr.sum(1)
    W = np.where(W > 0, W, 1.0)
    mr = (wr @ o) / W
    mc = (wc @ o) / W
    crr = (wr @ (o * o)) / W - mr * mr
    ccc = (wc @ (o * o)) / W - mc * mc
    crc = ((w @ o) @ o) / W - mr * mc
    tr = crr + ccc
    det = crr * ccc - crc * crc
    disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
    lmax = tr / 2 + disc
    lmin = np.maximum(tr / 2 - disc, 0.0)
    ratio = np.where(lmax > 0, lmin / np.where(lmax > 0, lmax, 1.0), 1.0)
    tx = crc
    ty = lmax - crr
    alt = np.abs(tx) + np.abs(ty) < 1e-12
    tx = np.where(alt, lmax - ccc, tx)
    ty = np.where(alt, crc, ty)
    alt2 = np.abs(tx) + np.abs(ty) < 1e-12
    tx = np.where(alt2, 1.0, tx)
    ty = np.where(alt2, 0.0, ty)
    nrm = np.hypot(tx, ty)
    return ratio, tx / nrm, ty / nrm


def _box_sampler(pr: np.ndarray, pc: np.ndarray, h: int, shape: tuple[int, int]):
    """``samp(A, dr, dc, outside_zero)``: ``A`` at the nearest pixel to each point + ``(dr, dc)``, kept
    within the point's box; outside the array 0 (``outside_zero``) or the edge value."""
    R, C = shape

    def samp(A, dr_, dc_, outside_zero):
        rr = np.clip(np.rint(pr + dr_).astype(np.int64), pr - h, pr + h)
        cc = np.clip(np.rint(pc + dc_).astype(np.int64), pc - h, pc + h)
        inside = (rr >= 0) & (rr < R) & (cc >= 0) & (cc < C)
        v = A[np.clip(rr, 0, R - 1), np.clip(cc, 0, C - 1)].astype(np.float64)
        return np.where(inside, v, 0.0) if outside_zero else v

    return samp

__all__ = ["box_filter"]
