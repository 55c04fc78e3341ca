r"""The round limb's pixels: an annulus about the initial circle on the lit side, its angular bins with a lit edge at
the limb.

Aerospace 2015 §5-6 (circular sigmoid, ``k`` estimated) and Mortari, D'Souza & Zanetti §VI (pixels between the radii
:math:`\hat r \pm \Delta r` on the lit side, Table 1); the fits on these pixels are :mod:`jaxlimb.pipeline.sphere.fits`.

Pixel selection (:func:`select_annulus`)
----------------------------------------
1. *Annulus*: pixels whose distance ``d`` from the initial centre satisfies
   :math:`|d - \hat r| \le \Delta r`, inside the frame.
   The half-width rule (:func:`annulus_halfwidth`, decision -- the papers say "a few
   pixels", "a function of the initial radius"):
   :math:`\Delta r = \max(\Delta r_{min}, f_r \hat r, 4\,\mathrm{rms}_{Taubin})`, capped at
   :math:`\max(\Delta r_{min}, \hat r / 2)`, with :math:`\Delta r_{min} = 6` px,
   :math:`f_r = 0.02`.  Six pixels cover :math:`\pm 4\sigma` of a 1.5 px Gaussian PSF, so
   both plateaus (``ymax`` inside, ``ymin`` outside) are sampled; ``4 rms`` keeps the limb
   inside the annulus when the initial circle is poor.  After a first fit, if the edge is
   broader than assumed (:math:`4.5 \times 1.7/k > \Delta r`; a logistic of steepness ``k``
   matches a Gaussian edge of :math:`\sigma \approx 1.7/k`) the annulus is widened to
   :math:`4.5 \times 1.7/k` and the fit repeated once.
2. *Lit side*: with a known lit direction ``d`` (the Sun direction projected at the body, or
   the middle of the front end's limb arc) only pixels within a half-angle :math:`\psi_{max}`
   of ``d`` (seen from the centre) are kept.  With the Sun known, the lit limb of a sphere is
   exactly the half-circle facing the Sun for every phase in (0, 180) deg (a limb point of
   image direction :math:`\psi` has normal :math:`(\cos\psi, \sin\psi, 0)`, so it is lit iff
   :math:`\cos\psi \sin\vartheta > 0`); :func:`lit_halfangle` removes a margin at the horns,
   larger for a crescent, where the terminator comes within :math:`\Delta r + 2` px of the limb
   (the terminator is the ellipse of semi-axes :math:`\hat r` and :math:`\hat r|\cos\vartheta|`,
   so along the ray at :math:`\psi` it lies at :math:`\hat r / \sqrt{\cos^2\psi/\cos^2\vartheta
   + \sin^2\psi}`).  Without the Sun, the half-angle is the front end's arc (points found
   on the limb) plus 2 deg.
3. *Contrast per angular bin*: the annulus is cut into bins of :data:`ANGULAR_BIN_DEG`
   (at least 4 px of arc); a bin whose inside-minus-outside contrast (means over the inner
   and outer quarters of the annulus) is below :data:`MIN_LIT_CONTRAST_FRAC` of the
   90th-percentile bin contrast is dropped: it removes the dark limb beyond the horns when
   the Sun is unknown, a terminator crossing the annulus, and bins spoiled by a bright star.
4. *Edge at the limb*: in each kept bin the edge position is estimated from the
   bin-normalised intensities :math:`z_n = (z - O_b)/(I_b - O_b)` as
   :math:`e_b = \hat r - \Delta r + 2\Delta r\,\langle z_n\rangle` (the integral of a
   unit step across the annulus); bins whose edge lies more than :data:`MAX_EDGE_OFFSET_PX`
   inside the 75th percentile of the bins' edges are dropped: there the edge is the
   terminator or the dark limb beyond a horn (e.g. the unlit sliver of a gibbous Moon, 1-2 px
   thick at 20-30 deg phase), which would pull a circle fitted to the lit limb inward.  When more than a third
   of the bins fall inward of that percentile the initial circle is off (a crescent's or a cropped limb's Taubin
   circle) and the edges are measured from their own first-order circle trend instead (:func:`_edge_offsets`).
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import ArcTooShortError, TooManyOutliersError
from ..stages import AnnulusSelection


#: Smallest half-width of the annulus (px): covers +-4 sigma of a 1.5 px blur (rule 1).
ANNULUS_MIN_PX = 6.0
#: Half-width as a fraction of the initial radius: a few px for the papers' 50-500 px Moons (rule 1).
ANNULUS_FRAC = 0.02
#: With a known Sun direction, the pixels within this angle (deg) of the horns are left out (rule 2).
HORN_MARGIN_DEG = 10.0
#: Width (deg) of the annulus' angular bins (at least 4 px of arc; rule 3).
ANGULAR_BIN_DEG = 5.0
#: Bins whose inside-minus-outside contrast is below this fraction of the 90th-percentile bin's are dropped (rule 3).
MIN_LIT_CONTRAST_FRAC = 0.3
#: Bins whose edge lies more than this (px) inside the limb's are dropped (rule 4).
MAX_EDGE_OFFSET_PX = 0.75


def annulus_halfwidth(radius: float, residual_rms: float) -> float:
    r"""Half-width ``dr`` (px) of the fitted annulus (module docstring, rule 1).

    Parameters
    ----------
    radius : float
        Initial radius :math:`\hat r` (px).
    residual_rms : float
        RMS radial residual of the front end's Taubin circle (px).

    Returns
    -------
    float
        :math:`\max(6, 0.02 \hat r, 4\,\mathrm{rms})`, capped at :math:`\max(6, \hat r / 2)` (px).
    """
    dr = max(ANNULUS_MIN_PX, ANNULUS_FRAC * radius, 4.0 * float(residual_rms))
    return float(min(dr, max(ANNULUS_MIN_PX, 0.5 * radius)))


def lit_halfangle(phase_rad: float | None, radius: float, dr: float, horn_margin_deg: float = HORN_MARGIN_DEG) -> float:
    """Half-angle (rad) of the usable lit limb about the Sun direction (module docstring, rule 2).

    ``pi/2 - horn_margin`` for a gibbous body; for a crescent (phase > 90 deg) also no more
    than the angle where the terminator comes within ``dr + 2`` px of the limb (the inner
    quarter of the annulus, where ``ymax`` is measured, must lie on the lit band); ``pi`` for a full
    body (the unlit sliver ``radius (1 - cos phase)`` under half a pixel).

    Parameters
    ----------
    phase_rad : float or None
        Phase angle (rad); ``None``: unknown (the gibbous value).
    radius, dr : float
        Radius and annulus half-width (px).
    horn_margin_deg : float
        Angle (deg) left out at each horn.

    Returns
    -------
    float
        Half-angle in ``[0, pi]`` (rad); 0 when no part of a crescent is thick enough.
    """
    base = math.pi / 2 - math.radians(horn_margin_deg)
    if phase_rad is None:
        return base
    if radius * (1.0 - math.cos(phase_rad)) < 0.5:  # the unlit sliver is below half a pixel: full
        return math.pi
    if phase_rad <= math.pi / 2:
        return base
    c2 = math.cos(phase_rad) ** 2
    psi = np.linspace(0.0, math.pi / 2, 2001)
    t_term = radius / np.sqrt(np.cos(psi) ** 2 / max(c2, 1e-300) + np.sin(psi) ** 2)
    ok = (radius - t_term) >= dr + 2.0
    if not ok.any():
        return 0.0
    # thickness decreases with psi: the last psi where the lit band is thick enough
    last = int(np.nonzero(ok)[0].max())
    return float(min(base, psi[last]))


def select_annulus(
    image: np.ndarray,
    center_rc,
    radius: float,
    dr: float,
    direction: tuple[float, float] | None,
    halfangle: float,
    mask: np.ndarray | None = None,
) -> AnnulusSelection:
    """Pixels of the annulus ``radius +- dr`` on the lit side (module docstring, rules 1-4).

    Parameters
    ----------
    image : np.ndarray (rows, cols)
    center_rc : (float, float)
        Centre ``(row, col)`` of the initial circle (px).
    radius, dr : float
        Its radius and the annulus half-width (px).
    direction : (float, float) or None
        Unit ``(d_row, d_col)`` toward the lit side; ``None``: all round.
    halfangle : float
        Half-angle (rad) of the lit-side window about ``direction``.
    mask : np.ndarray of bool, optional
        ``True`` = measured pixel (:mod:`jaxlimb.imaging.formats`); invalid pixels are neither limb nor background.

    Returns
    -------
    AnnulusSelection
        The kept pixels, their bins' levels and the arc's middle direction.

    Raises
    ------
    ArcTooShortError
        The annulus is in the frame but its lit-side window is not (fewer than 20 pixels there).
    TooManyOutliersError
        Fewer than 20 pixels survive (the limb is not in the frame, or no bin has contrast).
    """
    cr, cc = float(center_rc[0]), float(center_rc[1])
    coords, z, dsel = _annulus_window(np.asarray(image), (cr, cc), radius, dr, direction, halfangle, mask)
    ang = np.arctan2(coords[:, 0] - cr, coords[:, 1] - cc)
    inner = dsel <= radius - 0.5 * dr
    bins, nb = _angular_bins(ang, radius)
    outer = _outer_pixels(dsel, bins, nb, radius, dr, mask is not None)
    keep_bin, lev_in, lev_out, n_bins = _lit_bins(z, bins, nb, inner, outer, radius, dr)
    keep = keep_bin[bins]
    if np.count_nonzero(keep) < 20 or not np.any(inner & keep) or not np.any(outer & keep):
        raise TooManyOutliersError(
            f"no part of the limb annulus shows a lit edge ({int(np.count_nonzero(keep_bin))} of {n_bins} angular bins "
            f"with contrast; {int(np.count_nonzero(keep))} pixels)"
        )
    coords, z, dsel, ang, bins = coords[keep], z[keep], dsel[keep], ang[keep], bins[keep]
    inner, outer = inner[keep], outer[keep]
    e_in = dsel <= radius - dr + 1.0
    e_out = dsel >= radius + dr - 1.0
    return AnnulusSelection(
        coords=coords, z=z, center_rc=(cr, cc), radius=float(radius), dr=float(dr), direction=_mid_direction(ang),
        halfangle=float(halfangle), inner_level=float(np.median(z[inner])), outer_level=float(np.median(z[outer])),
        inner_edge_mean=float(np.mean(z[e_in])) if e_in.any() else float(np.median(z[inner])),
        outer_edge_mean=float(np.mean(z[e_out])) if e_out.any() else float(np.median(z[outer])),
        n_bins_kept=int(np.count_nonzero(keep_bin)), n_bins=n_bins, pixel_inner=lev_in[bins], pixel_outer=lev_out[bins])


def _mid_direction(ang: np.ndarray) -> tuple[float, float] | None:
    """Unit ``(d_row, d_col)`` of the mean direction of the polar angles ``ang``, ``None`` when they spread all round
    (mean resultant below 0.15)."""
    u = np.stack([np.sin(ang), np.cos(ang)], axis=1).mean(0)
    nu = float(np.linalg.norm(u))
    return (float(u[0] / nu), float(u[1] / nu)) if nu > 0.15 else None


NEAR_SKY_PX = 1.5
"""Where a validity mask leaves an angular bin fewer than two pixels in the annulus's outer half (a product whose
off-body pixels are blanked 1-2 px outside the limb, ``resampled_hmi.fits``), its sky level is taken from its valid
pixels this far (px) or farther outside the limb.  Without a mask the rule does not apply (a bin cut by the frame's
border is dropped)."""


def _outer_pixels(dsel: np.ndarray, bins: np.ndarray, nb: int, radius: float, dr: float, masked: bool) -> np.ndarray:
    """The sky side of the annulus: its outer half; with a validity mask (``masked``), also every pixel
    :data:`NEAR_SKY_PX` or farther outside the limb in the angular bins (``bins`` of ``nb``, :func:`_angular_bins`)
    with fewer than two pixels in that half."""
    outer = dsel >= radius + 0.5 * dr
    if not masked:
        return outer
    short = np.bincount(bins[outer], minlength=nb) < 2
    return outer | (short[bins] & (dsel >= radius + min(NEAR_SKY_PX, 0.5 * dr)))


def _annulus_window(img: np.ndarray, center_rc: tuple[float, float], radius: float, dr: float,
                    direction: tuple[float, float] | None, halfangle: float, mask: np.ndarray | None = None):
    """Rules 1-2: the pixels ``(coords, z, distance)`` of the annulus ``radius +- dr`` inside the frame, valid in
    ``mask`` and inside the lit-side window; the typed failures when too few are left."""
    R, C = img.shape
    cr, cc = center_rc
    rmax = radius + dr
    r0, r1 = max(0, int(math.floor(cr - rmax))), min(R, int(math.ceil(cr + rmax)) + 1)
    c0, c1 = max(0, int(math.floor(cc - rmax))), min(C, int(math.ceil(cc + rmax)) + 1)
    if r1 <= r0 or c1 <= c0:
        raise TooManyOutliersError("the limb annulus lies outside the frame: no pixels to fit")
    drow = np.arange(r0, r1, dtype=np.float64)[:, None] - cr
    dcol = np.arange(c0, c1, dtype=np.float64)[None, :] - cc
    d = np.sqrt(drow * drow + dcol * dcol)
    m = np.abs(d - radius) <= dr
    if mask is not None:
        m &= np.asarray(mask, bool)[r0:r1, c0:c1]
    windowed = direction is not None and halfangle < math.pi
    if windowed:
        with np.errstate(invalid="ignore", divide="ignore"):
            cosang = (drow * direction[0] + dcol * direction[1]) / np.where(d > 0, d, 1.0)
        m &= cosang >= math.cos(halfangle)
    ir, ic = np.nonzero(m)
    if ir.size < 20 and windowed and np.count_nonzero(np.abs(d - radius) <= dr) >= 20:

        # the limb is in the frame, but not its lit side: a cropped body facing the Sun out of the frame
        raise ArcTooShortError(
            f"the lit limb (within {math.degrees(halfangle):.0f} deg of the Sun direction) is outside the frame: "
            f"only {ir.size} pixels of the annulus on the lit side (need >= 20)"
        )
    if ir.size < 20:
        raise TooManyOutliersError(f"only {ir.size} pixels in the lit limb annulus (need >= 20)")
    coords = np.stack([ir + r0, ic + c0], axis=1).astype(np.float64)
    return coords, img[ir + r0, ic + c0].astype(np.float64), d[ir, ic]


def _angular_bins(ang: np.ndarray, radius: float) -> tuple[np.ndarray, int]:
    """Each pixel's angular bin (:data:`ANGULAR_BIN_DEG` wide, at least 4 px of arc) and the number of bins."""
    width = max(math.radians(ANGULAR_BIN_DEG), 4.0 / max(radius, 1e-9))
    nb = max(1, int(math.ceil(2 * math.pi / width)))
    return np.minimum(((ang + math.pi) / (2 * math.pi) * nb).astype(np.int64), nb - 1), nb


def _lit_bins(z: np.ndarray, bins: np.ndarray, nb: int, inner: np.ndarray, outer: np.ndarray, radius: float,
              dr: float):
    """Rules 3-4: angular bins (each pixel's of ``nb``, :func:`_angular_bins`) of the annulus with a lit edge at the
    limb.  Returns the bins kept, the bins' inner and outer levels and the number of bins with pixels."""
    # rule 3: contrast per angular bin (medians: robust to stars, hot pixels, craters)
    lev_in, n_in = bin_median(bins[inner], z[inner], nb)
    lev_out, n_out = bin_median(bins[outer], z[outer], nb)
    have = (n_in >= 2) & (n_out >= 2)
    contrast = np.full(nb, -np.inf)
    contrast[have] = lev_in[have] - lev_out[have]
    n_bins = int(np.count_nonzero(np.bincount(bins, minlength=nb)))
    keep_bin = have
    if have.any():
        ref = float(np.percentile(contrast[have], 90))
        keep_bin = have & (contrast >= MIN_LIT_CONTRAST_FRAC * ref) & (contrast > 0)
    # rule 4: the edge of each bin must be at the limb, not inside it (a terminator or the
    # dark limb beyond a horn): e_b = r - dr + 2 dr <z_n>, z_n the bin-normalised intensities
    if keep_bin.any():
        zn = np.clip((z - lev_out[bins]) / np.where(contrast[bins] > 0, contrast[bins], np.inf), -0.5, 1.5)
        s_zn = np.bincount(bins, weights=zn, minlength=nb)
        cnt = np.bincount(bins, minlength=nb)
        e_b = np.full(nb, np.nan)
        ok = keep_bin & (cnt > 0)
        e_b[ok] = radius - dr + 2.0 * dr * s_zn[ok] / cnt[ok]
        keep_bin = keep_bin & ~(_edge_offsets(e_b, ok, nb, MAX_EDGE_OFFSET_PX) < -MAX_EDGE_OFFSET_PX)
    return keep_bin, lev_in, lev_out, n_bins


def _edge_offsets(e_b: np.ndarray, ok: np.ndarray, nb: int, tol: float = 0.75, n_iter: int = 3) -> np.ndarray:
    """Rule 4: each bin's edge ``e_b`` less the limb's edge at its angle (NaN where not ``ok``).

    The limb's edge is the circle's: ``a + b cos(psi) + c sin(psi)`` (a small shift ``(c, b)`` and change ``a - r``
    of the initial circle, to first order), fitted to the bins whose edge is not inward of it (``n_iter`` passes
    from all ``ok`` bins), and then its 75th percentile residual: the initial circle of a crescent or a cropped
    limb is often off by 1-3 px (a Taubin circle through a short noisy arc), and its ``e_b`` then trend with the
    angle across the arc; measured against a constant, more than half of such an arc lies :data:`MAX_EDGE_OFFSET_PX`
    inward and would be dropped (benchmark row ``cropped`` 0: 149 deg phase, 25 of ~100 deg of lit limb kept).
    Fewer than 6 bins, a third or less of them inward of the 75th percentile by ``tol``, or a trend ``hypot(b, c)``
    within ``tol`` (a good initial circle): the constant of the 75th percentile alone (a terminator or dark limb
    entering at the ends of the arc is a minority of the bins; there the trend fit would take the centre error of
    benchmark row ``combined`` 3 from 0.016 to 0.026 px without need)."""
    idx = np.nonzero(ok)[0]
    off = np.full(nb, np.nan)
    if idx.size == 0:
        return off
    psi = (idx + 0.5) * (2.0 * math.pi / nb) - math.pi
    e = e_b[idx]
    model = np.full(idx.size, float(np.percentile(e, 75)))
    if idx.size >= 6 and np.count_nonzero(e < model - tol) > idx.size / 3:
        A = np.stack([np.ones_like(psi), np.cos(psi), np.sin(psi)], axis=1)
        use = np.ones(idx.size, bool)
        for _ in range(n_iter):
            coef = np.linalg.lstsq(A[use], e[use], rcond=None)[0]
            res = e - A @ coef
            use = res >= float(np.percentile(res, 75)) - tol
        if math.hypot(coef[1], coef[2]) > tol:  # the initial circle is off: measure from the trend
            model = A @ coef + float(np.percentile(e - A @ coef, 75))
    off[idx] = e - model
    return off


def bin_median(bins: np.ndarray, values: np.ndarray, nb: int) -> tuple[np.ndarray, np.ndarray]:
    """Median of ``values`` in each of ``nb`` bins (NaN where empty) and the counts (one sort).

    Parameters
    ----------
    bins : np.ndarray of int (n,)
        Each value's bin in ``[0, nb)``.
    values : np.ndarray (n,)
    nb : int
        Number of bins.

    Returns
    -------
    median : np.ndarray (nb,)
    counts : np.ndarray of int (nb,)
    """
    counts = np.bincount(bins, minlength=nb)
    med = np.full(nb, np.nan)
    if values.size == 0:
        return med, counts
    order = np.lexsort((values, bins))
    v = values[order]
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    ok = counts > 0
    lo = start[ok] + (counts[ok] - 1) // 2
    hi = start[ok] + counts[ok] // 2
    med[ok] = 0.5 * (v[lo] + v[hi])
    return med, counts


__all__ = ["annulus_halfwidth", "lit_halfangle", "select_annulus"]
