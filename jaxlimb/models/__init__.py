"""Limb models and their analytic Jacobians.

* the sigmoid models (LSF, CSF, ESF) of Sec. V of Mortari et al. 2016 (:mod:`.sigmoid`);
* the elliptical edge with an interior ramp and a varying limb level (:mod:`.ellipse_ramp`);
* the physical limb profile of a sunlit lunar-Lambert sphere blurred by a PSF, and the same widened by a
  Minnaert-like limb-brightening exponent (:mod:`.lunar_lambert`; its blur integral's quadrature:
  :mod:`.blur_quadrature`), and its columns toward a glow and toward an albedo that varies over the surface
  (:mod:`.profile_columns`);
* the limb-darkened disc of a self-luminous star (:mod:`.limb_darkened`) and the Sun's limb in the extreme
  ultraviolet, an optically thin corona over an opaque disc (:mod:`.corona`).

Every model carries its Jacobian beside its intensity and is checked by ``jaxlimb gradcheck``
(:mod:`.gradcheck`) against ``jax.jacfwd`` and central differences.
"""

from ._base import LimbModel as LimbModel, LimbParams as LimbParams, fused_model as fused_model
from .corona import CORONA as CORONA, CoronaParams as CoronaParams, corona_intensity as corona_intensity
from .ellipse_ramp import (
    ELLIPSE_RAMP as ELLIPSE_RAMP,
    EllipseRampParams as EllipseRampParams,
    ellipse_ramp_intensity as ellipse_ramp_intensity,
    ellipse_ramp_intensity_jac as ellipse_ramp_intensity_jac,
)
from .limb_darkened import (
    LIMB_DARKENED as LIMB_DARKENED,
    LimbDarkenedParams as LimbDarkenedParams,
    limb_darkened_intensity as limb_darkened_intensity,
    limb_darkening as limb_darkening,
)
from .lunar_lambert import (
    LIMB_PROFILE as LIMB_PROFILE,
    LIMB_PROFILE_MINNAERT as LIMB_PROFILE_MINNAERT,
    MinnaertProfileParams as MinnaertProfileParams,
    GlowProfileParams as GlowProfileParams,
    LIMB_PROFILE_GLOW as LIMB_PROFILE_GLOW,
    LIMB_PROFILE_ANISO as LIMB_PROFILE_ANISO,
    AnisoProfileParams as AnisoProfileParams,
    PROFILE_FIXED as PROFILE_FIXED,
    LimbProfileParams as LimbProfileParams,
    limb_profile_intensity as limb_profile_intensity,
    lunar_lambert_slope as lunar_lambert_slope,
    lunar_lambert_weight as lunar_lambert_weight,
)
from .sigmoid import (
    CIRCLE as CIRCLE,
    ELLIPSE as ELLIPSE,
    LINEAR as LINEAR,
    MODELS as MODELS,
    CircleParams as CircleParams,
    EllipseParams as EllipseParams,
    LinearParams as LinearParams,
    circle_intensity as circle_intensity,
    circle_intensity_jac as circle_intensity_jac,
    ellipse_coords as ellipse_coords,
    ellipse_intensity as ellipse_intensity,
    ellipse_intensity_jac as ellipse_intensity_jac,
    ellipse_points as ellipse_points,
    linear_intensity as linear_intensity,
    linear_intensity_jac as linear_intensity_jac,
)

#: Every limb model, by name (the sigmoids, the ramp, the physical profiles).
ALL_MODELS: dict[str, LimbModel] = {m.name: m for m in (LINEAR, CIRCLE, ELLIPSE, ELLIPSE_RAMP, LIMB_PROFILE,
                                                        LIMB_PROFILE_MINNAERT, LIMB_PROFILE_GLOW, LIMB_DARKENED,
                                                        LIMB_PROFILE_ANISO, CORONA)}
