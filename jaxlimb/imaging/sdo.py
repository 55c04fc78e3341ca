r"""Ground truth for the SDO Sun images of ``/work/shared/data/sun`` (see its MANIFEST).

:func:`sun_truth_from_header` computes the Sun's disk centre ``(row, col)`` in
the jaxlimb convention (0-based, pixel ``(0, 0)`` = centre of the first stored
pixel) and its apparent radius in pixels from a FITS header, exactly through
the header's WCS (``astropy.wcs``: ``CRPIX`` is 1-based, ``CDELT``, ``CROTA2``
or ``PCi_j``, the ``TAN`` projection).

Derivation
----------
Helioprojective coordinates (``HPLN``, ``HPLT``) put the Sun's centre at
``(0, 0)``.  ``wcs.world_to_pixel_values(0, 0)`` returns 0-based ``(x, y)``
pixel coordinates (astropy subtracts 1 from the FITS 1-based ``CRPIX``), i.e.
``col = x`` and ``row = y`` of the array as stored.  ``RSUN_OBS`` is the
observed angular radius :math:`\rho` (arcsec) of the photosphere's limb; the
limb is the small circle at angular distance :math:`\rho` from disk centre.  We
project 360 points of that circle,

.. math:: \text{lat} = \arcsin(\sin\rho\cos\phi),\qquad
          \text{lon} = \operatorname{atan2}(\sin\rho\sin\phi, \cos\rho),

through the WCS and return the mean pixel distance from the projected centre
(the projected limb is a circle to ~1e-6 px; the mean removes the first-order
effect of ``CRVAL`` not being exactly the disk centre).  For the HMI 512 image
this gives 973.96844 / 4.80000016 = 202.910 px to 1e-4 px (the ``TAN``
correction is :math:`\rho^2/3 \approx 7\cdot10^{-6}` relative).

The JPEG 2000 files written by Helioviewer store north up, i.e. their rows are
flipped with respect to the FITS data; pass ``rows_flipped=True`` (as
:func:`hmi_512_truth` does) to get row indices of the decoded JP2/PNG array.
For the 512 image ``CRPIX = 256.5`` is the array centre, so the flip does not
change the answer (255.5, 255.5).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError

#: File names in ``/work/shared/data/sun``.
HMI_512_PNG = "2023_01_31__03_39_23_200__SDO_HMI_HMI_continuum.png"
HMI_512_JP2 = "2023_01_31__03_39_23_200__SDO_HMI_HMI_continuum.jp2"
RESAMPLED_HMI_FITS = "resampled_hmi.fits"
AIA_171_FITS = "aia_171_level1.fits"


@dataclass(frozen=True)
class SunTruth:
    """Sun disk centre and radius in image pixels.

    Attributes
    ----------
    center_rc
        ``(row, col)`` of the disk centre, 0-based pixel-centre convention.
    radius_px
        Apparent radius of the limb (``RSUN_OBS``) in pixels.
    rsun_obs_arcsec
        The header's ``RSUN_OBS`` (arcsec).
    """

    center_rc: tuple[float, float]
    radius_px: float
    rsun_obs_arcsec: float


def sun_truth_from_header(header: Any, *, rows_flipped: bool = False, n_limb: int = 360,
                          ignore_rotation: bool = False) -> SunTruth:
    """Sun centre ``(row, col)`` and radius (px) from a FITS header, via ``astropy.wcs``.

    Parameters
    ----------
    header
        ``astropy.io.fits.Header`` (or a mapping of FITS keywords) with a
        helioprojective (``HPLN``/``HPLT``) celestial WCS and ``RSUN_OBS`` in arcsec.
    rows_flipped
        The image array is stored with rows reversed relative to the FITS data
        (Helioviewer JPEG 2000, and PNGs decoded from them).
    n_limb
        Number of projected limb points averaged for the radius.
    ignore_rotation
        Map with ``CROTA2`` set to 0.  ``resampled_hmi.fits`` (``CROTA2 = 179.93``) is a resampled product whose
        pixels no longer carry that rotation: its disc, its NaN mask and the limb fit agree with the centre this gives,
        0.30 px from the rotated WCS's (``benchmarks/sun_limb.py``).

    Raises
    ------
    ConfigError
        Missing ``RSUN_OBS``/WCS keywords or a WCS that cannot map the Sun centre.
    """
    from astropy import units as u
    from astropy.wcs import WCS

    header, rsun = _checked_header(header, ignore_rotation)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = WCS(header, naxis=2)
    units = [u.Unit(s) for s in w.world_axis_units]
    rho = math.radians(rsun / 3600.0)
    phi = np.linspace(0.0, 2.0 * np.pi, n_limb, endpoint=False)
    lat = np.arcsin(np.sin(rho) * np.cos(phi))
    lon = np.arctan2(np.sin(rho) * np.sin(phi), np.cos(rho))
    lon_w = (lon * u.rad).to_value(units[0])
    lat_w = (lat * u.rad).to_value(units[1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        x0, y0 = w.world_to_pixel_values(0.0, 0.0)
        xl, yl = w.world_to_pixel_values(lon_w, lat_w)
    x0, y0 = float(x0), float(y0)
    if not (math.isfinite(x0) and math.isfinite(y0)):
        raise ConfigError("header WCS cannot map the Sun centre (0, 0) to pixels")
    radius = float(np.mean(np.hypot(np.asarray(xl) - x0, np.asarray(yl) - y0)))
    row = y0
    if rows_flipped:
        ny = int(header.get("NAXIS2", 0))
        if ny <= 0:
            raise ConfigError("rows_flipped=True needs NAXIS2 in the header")
        row = (ny - 1) - y0
    return SunTruth(center_rc=(row, x0), radius_px=radius, rsun_obs_arcsec=rsun)


def _checked_header(header: Any, ignore_rotation: bool) -> tuple[Any, float]:
    """``header`` as a FITS header (``CROTA2`` set to 0 with ``ignore_rotation``) with its WCS keywords checked,
    and its ``RSUN_OBS`` (arcsec, finite and > 0)."""
    from astropy.io import fits

    if not isinstance(header, fits.Header):
        try:
            header = fits.Header(dict(header))
        except Exception as e:
            raise ConfigError(f"header must be a FITS header or mapping, got {type(header).__name__}: {e}") from None
    if ignore_rotation and "CROTA2" in header:
        header = header.copy()
        header["CROTA2"] = 0.0
    if "RSUN_OBS" not in header:
        raise ConfigError("header has no RSUN_OBS (observed solar radius, arcsec)")
    rsun = float(header["RSUN_OBS"])
    if not (math.isfinite(rsun) and rsun > 0):
        raise ConfigError(f"header RSUN_OBS must be a finite angle > 0 arcsec, got {rsun!r}")
    for k in ("CRPIX1", "CRPIX2", "CDELT1", "CDELT2", "CTYPE1", "CTYPE2"):
        if k not in header and not (k.startswith("CDELT") and "CD1_1" in header):
            raise ConfigError(f"header is missing the WCS keyword {k}")
    return header, rsun


def hmi_512_truth() -> SunTruth:
    """Truth of the HMI 512 PNG/JP2 from the MANIFEST: centre (255.5, 255.5), radius 202.91 px."""
    # CRPIX1 = CRPIX2 = 256.5 (1-based): 0-based centre 255.5 (CRVAL = 0); radius RSUN_OBS / CDELT (arcsec, arcsec/px)
    rsun_obs_arcsec = 973.96844
    return SunTruth(center_rc=(255.5, 255.5), radius_px=rsun_obs_arcsec / 4.80000016, rsun_obs_arcsec=rsun_obs_arcsec)


__all__ = [
    "AIA_171_FITS",
    "HMI_512_JP2",
    "HMI_512_PNG",
    "RESAMPLED_HMI_FITS",
    "SunTruth",
    "hmi_512_truth",
    "sun_truth_from_header",
]
