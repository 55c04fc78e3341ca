r"""The ellipsoid strategy of :func:`jaxlimb.pipeline.locate`: the Earth and any spheroid whose flattening the frame
resolves (a giant planet; :func:`jaxlimb.pipeline.bodies.body_strategy`), its limb an ellipse.

Mortari, D'Souza & Zanetti, "Image Processing of Illuminated Ellipsoid" (J. Spacecraft and Rockets 53(3), 2016,
doi:10.2514/1.A33342), §III-V and Fig. 1-2:

1. **Limb candidates**: a front end of :mod:`jaxlimb.imaging` (the Earth is a circle to 0.34 %), or, when it
   lands on cloud edges, the disc's sunward extreme and the range prior's radius (:mod:`.start`); for another body
   whose limb the hints predict (SPICE), the predicted-limb front end (:mod:`.predicted_start`); the start
   ellipse traced against the sky (:mod:`.trace`: the outermost edge along rays from the centre).
2. **Predicted shape** (Eq. 2-9): with ``R_body_to_camera`` the limb cone of the spheroid at the current position
   gives the image ellipse's axis ratio ``rho`` and orientation ``theta``
   (:func:`jaxlimb.geometry.ellipsoid.image_conic`), held in the fit.
3. **Edge fit** (§V-C, :mod:`.edge`): the elliptical sigmoid with an interior ramp
   (:data:`jaxlimb.models.ELLIPSE_RAMP`) on a band of ``band_px`` about the ellipse on the lit arc.
4. **Position** (§IV, Fig. 2): the fitted ellipse's cone, its axis and ``b'`` (Eq. 8), and the range iteration
   (:mod:`jaxlimb.geometry.earth_cone`); steps 2-4 repeat while the prediction moves the ellipse.
5. **Physical profile** (:mod:`.profile`): with the Sun direction known the same pixels are refitted with the
   blurred lunar-Lambert radiance (:mod:`jaxlimb.pipeline.profile`), which removes the edge models' bias from the
   limb's bright rim; widened by a glow or an anisotropic blur when a score test asks for it.
6. **Output** (:mod:`.center`): the body centre's image (not the ellipse centre), line of sight and range, the
   covariance through the central-difference Jacobian of steps 4-5.

An albedo-patchy limb (clouds) is measured from its traced rays as well (:mod:`.patchy`); the two estimates'
difference is model error.  Without ``R_body_to_camera`` the ellipse is free: the range is ``(Re + h)/a'`` and the
centre offset cannot be signed, so it is carried as a uniform model error (or marginalised over the poles the
Sun's declination bound allows, :mod:`.pole_prior`).

``atmosphere_km`` (hint) is the height of the edge measured above the solid body: ``0`` for a clear limb,
the cloud-top height where clouds make the limb (~2 km low stratus, 5-8 km mid-level, 10-12 km cirrus).  A
1 km error biases the range by 1/6378, not the line of sight.  A glow fainter and thinner than a pixel cannot
be told from the edge; the covariance carries it as a consider parameter (``EllipsoidOptions.unresolved_glow``).
"""

from .body import Ellipsoid as Ellipsoid
from .model import EllipsoidModel as EllipsoidModel
from ..options import EllipsoidOptions as EllipsoidOptions

__all__ = ["Ellipsoid", "EllipsoidModel", "EllipsoidOptions"]
