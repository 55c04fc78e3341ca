"""Sigmoid limb models (LSF, CSF, ESF) and their analytic Jacobians, Sec. V of Mortari et al. 2016."""

from ._base import LimbModel as LimbModel, LimbParams as LimbParams
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
