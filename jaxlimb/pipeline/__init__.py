"""The limb pipeline: ``locate(image, camera, hints, options)`` composing front end, limb pixels, edge fit, profile
refit, body-centre mapping and checks over body strategies (:mod:`jaxlimb.pipeline.stages`); the measurement
types; the checks as typed errors.

Public API::

    locate(image, camera=None, hints=None, options=None) -> LimbMeasurement   (every body: sphere, a sphere whose
        limb the hints predict, ellipsoid (hints body "earth"), disc (hints body "sun"); jaxlimb.pipeline.bodies)
    LocateOptions(front_end, model, profile, shape, ellipsoid, gradient, scanline, ...)
    FrontEnd, LimbModelKind, Profile, BodyShape   (the options' Enums); EllipsoidOptions
    LimbMeasurement, EllipseResult           (result types, ``to_json()``)
    save_locate_figure(image, measurement, path, selected_pixels=None, truth=None)   (with edge_residuals: the
        image's own edge along the fitted limb's normals against that limb)
    checks: CenterOutOfFieldError, check_jump, check_radius_prior, check_size, check_center_in_field
    the round limb's fits: select_annulus, annulus_halfwidth, lit_halfangle, fit_circle_annulus, fit_sphere_annulus,
        fit_ellipse_annulus, AnnulusSelection, RefineResult
    the Sun's limb-darkened disc: fit_limb_darkened, SunLimbFit

Sub-packages: :mod:`~jaxlimb.pipeline.sphere` (round bodies), :mod:`~jaxlimb.pipeline.ellipsoid` (the Earth),
:mod:`~jaxlimb.pipeline.profile` (the physical limb profile both refit with).
"""

from .checks import (
    CenterOutOfFieldError as CenterOutOfFieldError,
    check_center_in_field as check_center_in_field,
    check_jump as check_jump,
    check_radius_prior as check_radius_prior,
    check_size as check_size,
    jump_threshold as jump_threshold,
)
from .options import EllipsoidOptions as EllipsoidOptions
from .figure import edge_residuals as edge_residuals, save_locate_figure as save_locate_figure
from .locate import locate as locate
from .options import (
    BodyShape as BodyShape,
    FrontEnd as FrontEnd,
    LimbModelKind as LimbModelKind,
    LocateOptions as LocateOptions,
    Profile as Profile,
)
from .result import (CENTER_NAMES as CENTER_NAMES, EllipseResult as EllipseResult, LimbMeasurement as LimbMeasurement,
                     covariance_block as covariance_block)
from .sphere.annulus import annulus_halfwidth as annulus_halfwidth, lit_halfangle as lit_halfangle, select_annulus as select_annulus
from .sphere.fits import (
    fit_circle_annulus as fit_circle_annulus,
    fit_ellipse_annulus as fit_ellipse_annulus,
    fit_sphere_annulus as fit_sphere_annulus,
)
from .sphere.sun import SunLimbFit as SunLimbFit, fit_limb_darkened as fit_limb_darkened
from .stages import AnnulusSelection as AnnulusSelection, RefineResult as RefineResult

__all__ = [
    "AnnulusSelection",
    "BodyShape",
    "CENTER_NAMES",
    "CenterOutOfFieldError",
    "EllipseResult",
    "EllipsoidOptions",
    "FrontEnd",
    "LimbMeasurement",
    "LimbModelKind",
    "LocateOptions",
    "Profile",
    "RefineResult",
    "SunLimbFit",
    "annulus_halfwidth",
    "check_center_in_field",
    "check_jump",
    "check_radius_prior",
    "check_size",
    "covariance_block",
    "edge_residuals",
    "fit_circle_annulus",
    "fit_ellipse_annulus",
    "fit_limb_darkened",
    "fit_sphere_annulus",
    "jump_threshold",
    "lit_halfangle",
    "locate",
    "save_locate_figure",
    "select_annulus",
]
