"""The limb pipeline: ``locate(image, camera, hints, options)`` composing front end, refinement,
body-centre correction and checks; the measurement types; the checks as typed errors.

Public API::

    locate(image, camera=None, hints=None, options=None) -> LimbMeasurement   (every body: sphere,
        ellipsoid (hints body "earth"), disc (hints body "sun"); jaxlimb.pipeline.bodies)
    LocateOptions(front_end, model, solver, estimate_k, k_fixed, annulus_px, shape, ellipsoid, ...)
    FrontEnd, LimbModelKind, Profile, BodyShape   (the options' Enums); EllipsoidOptions
    LimbMeasurement, EllipseResult           (result types, ``to_json()``)
    save_locate_figure(image, measurement, path, selected_pixels=None, truth=None)
    checks: CenterOutOfFieldError, check_jump, check_radius_prior, check_size, check_center_in_field
    refinement: select_annulus, annulus_halfwidth, lit_halfangle, fit_circle_annulus, fit_sphere_annulus
    sphere image: SphereImage, sphere_from_ellipse_center, sphere_from_circle_fit
    physical limb profile: sphere_from_circle_fit (the models LIMB_PROFILE, LIMB_DARKENED, ELLIPSE_RAMP
        live in jaxlimb.models and are re-exported here for older imports)
    the Sun's limb-darkened disc: fit_limb_darkened, SunLimbFit
"""

from .checks import (
    CenterOutOfFieldError as CenterOutOfFieldError,
    check_center_in_field as check_center_in_field,
    check_jump as check_jump,
    check_radius_prior as check_radius_prior,
    check_size as check_size,
    jump_threshold as jump_threshold,
)
from .figure import save_locate_figure as save_locate_figure
from .locate import locate as locate
from .earth import EllipsoidOptions as EllipsoidOptions
from .options import (
    BodyShape as BodyShape,
    FrontEnd as FrontEnd,
    LimbModelKind as LimbModelKind,
    LocateOptions as LocateOptions,
    Profile as Profile,
)
from .refine import (
    AnnulusSelection as AnnulusSelection,
    RefineResult as RefineResult,
    annulus_halfwidth as annulus_halfwidth,
    fit_circle_annulus as fit_circle_annulus,
    fit_ellipse_annulus as fit_ellipse_annulus,
    fit_sphere_annulus as fit_sphere_annulus,
    lit_halfangle as lit_halfangle,
    select_annulus as select_annulus,
)
from ..models import (
    LIMB_DARKENED as LIMB_DARKENED,
    LIMB_PROFILE as LIMB_PROFILE,
    LimbDarkenedParams as LimbDarkenedParams,
    LimbProfileParams as LimbProfileParams,
    limb_profile_intensity as limb_profile_intensity,
)
from ..geometry.sphere_image import sphere_from_circle_fit as sphere_from_circle_fit
from .sun_profile import SunLimbFit as SunLimbFit, fit_limb_darkened as fit_limb_darkened
from .result import EllipseResult as EllipseResult, LimbMeasurement as LimbMeasurement
from ..geometry.sphere_image import SphereImage as SphereImage, sphere_from_ellipse_center as sphere_from_ellipse_center

__all__ = [
    "LIMB_DARKENED",
    "LimbDarkenedParams",
    "SunLimbFit",
    "fit_limb_darkened",
    "LIMB_PROFILE",
    "LimbProfileParams",
    "limb_profile_intensity",
    "sphere_from_circle_fit",
    "AnnulusSelection",
    "CenterOutOfFieldError",
    "EllipseResult",
    "LimbMeasurement",
    "BodyShape",
    "EllipsoidOptions",
    "FrontEnd",
    "LimbModelKind",
    "LocateOptions",
    "Profile",
    "RefineResult",
    "SphereImage",
    "annulus_halfwidth",
    "check_center_in_field",
    "check_jump",
    "check_radius_prior",
    "check_size",
    "fit_circle_annulus",
    "fit_ellipse_annulus",
    "fit_sphere_annulus",
    "jump_threshold",
    "lit_halfangle",
    "locate",
    "save_locate_figure",
    "select_annulus",
    "sphere_from_ellipse_center",
]
