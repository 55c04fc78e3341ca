"""A second renderer, written independently of the pipeline's own assumptions and code.

Per-pixel supersampled ray casting of a sunlit ellipsoid in NumPy (no :mod:`jaxlimb.geometry`,
:mod:`jaxlimb.render` or :mod:`jaxlimb.pipeline` code), with reflectance laws the pipeline's
profile does not implement (Hapke, Minnaert, Lommel-Seeliger with opposition surge), albedo
maps (lunar maria, the Earth's oceans, continents and clouds), exponential glows above the
limb, non-Gaussian PSFs (Airy, defocus, motion smear), 8/12-bit sensors, JPEG, stars and hot
pixels, and the exact truth: the image of the body centre, the limb ellipse, the range.

Public API::

    moon_case(family, rng) -> Case          # families: MOON_FAMILIES
    earth_case(family, rng, far=None, ablate=()) -> Case   # EARTH_FAMILIES; ablate: ABLATIONS
    earth_full_disc_case(family, rng) -> Case   # EARTH_FULL_DISC_FAMILIES (deep space, EPIC-like)
    Body, Pinhole, limb_truth, cast         # geometry
    Surface, render_radiance                # blurred, pixel-integrated radiance
    Photometry, Reflectance, MariaMap, SpotsMap, EarthMap, Psf, PsfKind, Glow, SensorSpec, digitise
"""

from .families import ABLATIONS, EARTH_FAMILIES, EARTH_FULL_DISC_FAMILIES, MOON_FAMILIES, Case, earth_case, earth_full_disc_case, moon_case
from .geometry import Body, LimbTruth, Pinhole, cast, limb_truth
from .optics import Glow, Psf, PsfKind
from .raster import Surface, render_radiance
from .sensor import SensorSpec, digitise
from .surface import EarthMap, MariaMap, Photometry, Reflectance, SpotsMap

__all__ = ["ABLATIONS", "EARTH_FAMILIES", "EARTH_FULL_DISC_FAMILIES", "MOON_FAMILIES", "Body", "Case", "EarthMap", "Glow", "LimbTruth", "MariaMap",
           "Photometry", "Pinhole", "Psf", "PsfKind", "Reflectance", "SensorSpec", "SpotsMap", "Surface", "cast", "digitise",
           "earth_case", "earth_full_disc_case", "limb_truth", "moon_case", "render_radiance"]
