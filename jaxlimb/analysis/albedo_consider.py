r"""What an unknown albedo field does to a ``locate`` answer: the consider term its covariance carries.

``locate``'s covariance of the physical profile carries an unknown albedo field's consider term, ``tau^2 G U U^T G^T``,
where its other model-error terms do not already (:mod:`jaxlimb.pipeline.profile.albedo_prior`: the field, its
amplitude from what of the residuals varies along the limb, the term).  :func:`albedo_consider_of` gives the term of a
:class:`~jaxlimb.analysis.located.LocatedFit`, mapped to the body centre, with the field's amplitude and length,
beside ``locate``'s centre covariance.  ``benchmarks/albedo_consider.py`` measures it on the independent renderer's
families.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models import LimbProfileParams
from ..models.lunar_lambert import profile_model
from ..pipeline.profile.albedo_prior import albedo_consider
from ..pipeline.profile.model_error import signed_distance, weighted_system
from ..pipeline.report import covariance
from ..pipeline.result import covariance_block
from .located import LocatedFit

@dataclass(frozen=True)
class AlbedoConsider:
    """:func:`albedo_consider_of`'s answer.

    Attributes
    ----------
    tau, ell_deg : the field's amplitude (relative albedo sigma) and correlation length (deg).
    center : the term on the body centre, ``(2, 2)`` px^2.
    locate : ``locate``'s centre covariance, ``(2, 2)`` px^2 (the term included where its other terms did not carry
        it).
    """

    tau: float
    ell_deg: float
    center: np.ndarray
    locate: np.ndarray


def center_map(lf: LocatedFit) -> np.ndarray:
    """The body centre's derivative by the fit's free parameters: the rows ``center_r, center_c`` of the Jacobian
    ``locate``'s covariance stage maps the fit's covariance with (:func:`jaxlimb.pipeline.report.covariance`).

    Parameters
    ----------
    lf : LocatedFit
        :func:`~jaxlimb.analysis.located.located_fit`'s answer.

    Returns
    -------
    np.ndarray (2, q)
        ``d (row, col) / d x`` over ``lf.free``.
    """
    cov = covariance(lf.final, lf.geo)
    return cov.jacobian[[cov.names.index("center_r"), cov.names.index("center_c")]]


def albedo_consider_of(lf: LocatedFit) -> AlbedoConsider | None:
    """The albedo field's consider covariance of a ``locate`` answer (module docstring); ``None`` unless its final fit
    is the physical profile.

    Parameters
    ----------
    lf : LocatedFit
        :func:`~jaxlimb.analysis.located.located_fit`'s answer.

    Returns
    -------
    AlbedoConsider or None
    """
    rr = lf.final
    p = rr.fit.params
    if not isinstance(p, LimbProfileParams):
        return None
    J, r, padded, w = weighted_system(rr, profile_model(p))
    coords = np.asarray(rr.data.coords, float)
    Ca, tau, ell = albedo_consider(p, coords, J, r, w, signed_distance(p, coords, padded))
    G = center_map(lf)
    return AlbedoConsider(tau, ell, G @ Ca @ G.T, covariance_block(lf.measurement.covariance))


__all__ = ["AlbedoConsider", "albedo_consider_of", "center_map"]
