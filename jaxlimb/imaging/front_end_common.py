"""What both front ends share: the §3 prior (from the hints, else measured on the image), its radius band and Check
3/4 on a fitted radius, Check 3 of a variegated body's region, the zone a validity mask leaves usable and the band
about a variegated body's outline."""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..errors import RadiusInconsistentError, TooManyOutliersError
from ..geometry.camera import Camera
from .crop import BodyRegion
from .prior import Hints, Prior, PriorOptions, check_prior, prior_from_hints, prior_from_image


def resolve_prior(
    img: np.ndarray,
    region: BodyRegion,
    prior: Prior | None,
    hints: Hints | None,
    camera: Camera | None,
    popt: PriorOptions,
) -> Prior:
    """The prior to use: given, from hints (+camera, Check 1), or measured on the image."""
    if prior is None and hints is not None:
        prior = prior_from_hints(hints, camera, options=popt, check=True)
        if prior is not None and camera is None:

            check_prior(prior, img.shape, popt)
    if prior is None:
        prior = prior_from_image(img, popt, region=region)
    return prior


def check_region_inside(center_rc, radius: float, region: BodyRegion, max_outside_frac: float) -> None:
    """Check 3 of a variegated body (:attr:`~.crop.BodyRegion.dark_surface`): the lit region of
    :func:`~.crop.detect_body` lies inside the limb circle (a margin of a few pixels and one working-image block for a
    glow and the block averaging), else :class:`TooManyOutliersError`.

    The strongest gradients of a variegated body (the Earth's cloud edges, dark oceans, Lambert limb darkening at
    low phase) can be edges inside the disc; a circle through them leaves much of the body outside, which no
    limb can do."""
    if not region.dark_surface:  # a crescent's first circle may be poor yet refined well: only a variegated body's
        return
    out = region_outside_fraction(center_rc, radius, region)
    if out > max_outside_frac:
        raise TooManyOutliersError(
            f"Check 3: the circle through the strongest edges (radius {radius:.1f} px) leaves {100 * out:.0f} % of the "
            "lit region outside it: those edges lie inside the body (albedo or cloud edges), not on its limb")


def region_outside_fraction(center_rc, radius: float, region: BodyRegion) -> float:
    """The fraction of the lit region of :func:`~.crop.detect_body` outside the circle (beyond a margin of
    ``max(3 px, 3 %)`` of the radius and one working-image block, for a glow and the block averaging); 0 for an
    empty region."""
    f = region.factor
    rr, cc = np.nonzero(region.mask_small)
    if rr.size == 0:
        return 0.0
    d = np.hypot(rr * f + 0.5 * (f - 1) - center_rc[0], cc * f + 0.5 * (f - 1) - center_rc[1])
    return float(np.mean(d > radius + max(3.0, 0.03 * radius) + f))


def radius_band(prior: Prior, region: BodyRegion) -> tuple[float, float]:
    """Radius band of RANSAC and Check 4 (:attr:`Prior.radius_range`)."""
    return prior.radius_range


def check_radius(radius: float, prior: Prior, band: tuple[float, float]) -> None:
    """Check 4: the fitted radius lies in the prior band, else :class:`RadiusInconsistentError`."""
    lo, hi = band
    if not (lo <= radius <= hi):
        raise RadiusInconsistentError(
            f"fitted radius {radius:.4g} px is outside the range [{lo:.4g}, {hi:.4g}] px expected from the "
            f"{prior.source} prior p_r = {prior.expected_radius_px:.4g} px (uncertainty "
            f"{100 * prior.radius_uncertainty_frac:.0f} %)"
        )


def valid_zone(mask: np.ndarray, reach: int) -> np.ndarray:
    """Pixels farther than ``reach`` px from every invalid pixel of ``mask`` (frame borders are not invalid)."""
    from scipy import ndimage

    if mask.all():
        return mask
    return ndimage.binary_erosion(mask, structure=np.ones((3, 3), bool), iterations=max(1, reach), border_value=1)


def outline_band(region: BodyRegion, window: tuple[int, int, int, int], frac: float = 0.06, min_px: float = 8.0) -> np.ndarray:
    """Pixels of ``window`` (``r0, r1, c0, c1``) within ``max(min_px, frac R)`` of the outline of the detected region
    (``R`` its equivalent radius): where a variegated body's limb can be (:func:`~.crop.dark_surface_region`).  Its
    strongest gradients are otherwise cloud or coast edges inside the disc; near the outline they are the limb
    where something bright stands on it, and RANSAC keeps the circle of those arcs."""
    f = region.factor
    w = max(min_px, frac * math.sqrt(region.area_px / math.pi))
    k = max(1, int(math.ceil(w / f)))
    m = np.ascontiguousarray(region.mask_small, dtype=np.uint8)
    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
    band_small = (cv2.dilate(m, ker) > 0) & ~(cv2.erode(m, ker) > 0)
    r0, r1, c0, c1 = window
    rows = np.clip((np.arange(r0, r1) // f), 0, band_small.shape[0] - 1)
    cols = np.clip((np.arange(c0, c1) // f), 0, band_small.shape[1] - 1)
    return band_small[np.ix_(rows, cols)]


__all__ = ["check_radius", "check_region_inside", "outline_band", "radius_band", "region_outside_fraction",
           "resolve_prior", "valid_zone"]
