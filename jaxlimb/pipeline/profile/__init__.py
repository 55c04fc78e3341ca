"""The physical limb profile of a sunlit body (:data:`jaxlimb.models.LIMB_PROFILE`: the blurred lunar-Lambert
radiance) fitted to a limb's pixels, as the sphere's and the ellipsoid's profile-refit stage.

Modules: :mod:`.fit` (start, fit, clipped pixels), :mod:`.passes` (the fit with the sphere's shape iterated),
:mod:`.widen` (limb brightening, anisotropic blur), :mod:`.glow` (a glow above the limb), :mod:`.patchy` (sectors
down-weighted), :mod:`.model_error` (the weighted system and the covariance's model-error terms).
"""

from .fit import fit_lunar_profile as fit_lunar_profile

__all__ = ["fit_lunar_profile"]
