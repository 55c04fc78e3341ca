"""Geometry: pinhole camera, ellipsoid limb cone and image conic, terminator, Earth offset and
range iteration, horizon-based navigation, attitude, ephemerides and the observer position.

Submodules: :mod:`~jaxlimb.geometry.camera`, :mod:`~jaxlimb.geometry.hints` (the navigation prior),
:mod:`~jaxlimb.geometry.bodies` (the one table of body radii), :mod:`~jaxlimb.geometry.ellipsoid` (Eq. 1-9 of
Mortari et al. 2016), :mod:`~jaxlimb.geometry.conic` (image conics and ellipses), :mod:`~jaxlimb.geometry.terminator`, :mod:`~jaxlimb.geometry.earth`
(Sec. IV), :mod:`~jaxlimb.geometry.horizon` (Christian-Robinson), :mod:`~jaxlimb.geometry.attitude`,
:mod:`~jaxlimb.geometry.ephemeris` (offline DE421), :mod:`~jaxlimb.geometry.navigation`.
"""

from .bodies import BODY_TABLE as BODY_TABLE, Body as Body
from .camera import Camera as Camera, sphere_image_ellipse as sphere_image_ellipse
from .conic import conic_to_ellipse as conic_to_ellipse, ellipse_to_conic as ellipse_to_conic
from .ellipsoid import (
    ImageConic as ImageConic,
    LimbCone as LimbCone,
    image_conic as image_conic,
    limb_cone as limb_cone,
    limb_cone_matrix as limb_cone_matrix,
    projected_center as projected_center,
)
from .hints import Hints as Hints
from .navigation import (
    NavigationSolution as NavigationSolution,
    navigate as navigate,
    observer_position as observer_position,
    sphere_from_circle as sphere_from_circle,
    sphere_from_ellipse as sphere_from_ellipse,
)
from .terminator import terminator_ellipse as terminator_ellipse, terminator_image as terminator_image
