r"""The fit behind a :func:`jaxlimb.pipeline.locate` answer: its model, pixels, weights, free and held
parameters, and the body-centre mapping of its parameters.

:func:`located_fit` runs ``locate`` (the measurement users get) and the same stages of its body strategy
(prepare, candidates, limb pixels, edge fit, refit, body-centre mapping: ``locate``'s composition, with its
front-end fallback) to keep the final fit they produce, checks that the two agree (centre to 1e-9 px) and
returns both.  The instruments study that fit: the posterior of its parameters
(:mod:`jaxlimb.analysis.posterior`), the solvers on its problem (:mod:`jaxlimb.analysis.compare`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import numpy as np

from ..errors import ConfigError
from ..models import (CIRCLE, CORONA, ELLIPSE, ELLIPSE_RAMP, LIMB_DARKENED, CircleParams, CoronaParams, EllipseParams,
                      EllipseRampParams, LimbDarkenedParams, LimbModel, LimbParams, LimbProfileParams)
from ..models.lunar_lambert import profile_model
from ..pipeline import LimbMeasurement, locate
from ..pipeline.bodies import body_strategy
from ..pipeline.frame import other_candidates, prepare
from ..pipeline.report import covariance
from ..pipeline.sphere.edge import InitialCircleOffError
from ..pipeline.sphere.predicted import PredictedLimbSphere

#: Largest difference (px) between ``locate``'s centre and the replayed stages' before :func:`located_fit` refuses.
AGREEMENT_PX = 1e-9


def model_of(params: LimbParams) -> LimbModel:
    """The limb model whose parameters ``params`` are (every model ``locate`` fits).

    Parameters
    ----------
    params : LimbParams
        Circle, ellipse, elliptical-ramp, limb-darkened or limb-profile parameters.

    Returns
    -------
    LimbModel
        The model of that parameter type (for a profile, the one of its reflectance law).
    """
    if isinstance(params, LimbProfileParams):
        return profile_model(params)
    table = {CircleParams: CIRCLE, EllipseParams: ELLIPSE, EllipseRampParams: ELLIPSE_RAMP,
             LimbDarkenedParams: LIMB_DARKENED, CoronaParams: CORONA}
    return table[type(params)]


@dataclass(frozen=True)
class LocatedFit:
    """``locate``'s answer and the final fit it came from.

    Attributes
    ----------
    measurement : the :class:`~jaxlimb.pipeline.LimbMeasurement` ``locate`` returned.
    final : the final fit (:class:`~jaxlimb.pipeline.stages.RefineResult`: ``fit``, ``data``, ``fixed``).
    geo : its body-centre mapping (:class:`~jaxlimb.pipeline.stages.BodyCenter`).
    edge : the edge fit the mapping starts from (:class:`~jaxlimb.pipeline.stages.EdgeFit`).
    names, matrix : ``locate``'s covariance over the mapped quantities and the other free parameters.
    crlb : the Cramér--Rao sigmas ``locate`` reports (``None`` when not computed).
    """

    measurement: LimbMeasurement
    final: Any
    geo: Any
    names: tuple[str, ...]
    matrix: np.ndarray
    crlb: dict[str, float] | None
    frame: Any
    body: Any
    edge: Any

    @property
    def model(self) -> LimbModel:
        return model_of(self.final.fit.params)

    @property
    def params(self) -> LimbParams:
        return self.final.fit.params

    @property
    def free(self) -> tuple[str, ...]:
        return tuple(self.final.fit.free)

    @property
    def data(self) -> Any:
        """The fit's pixels: ``coords`` (ideal px), ``z``, ``weights`` (or ``None``), ``offset``, ``scale``."""
        return self.final.data

    @property
    def sigma(self) -> float:
        """The fit's residual sigma :math:`\\hat\\sigma` in the units of ``data.z``."""
        return float(np.sqrt(max(float(self.final.fit.sigma2), 1e-300)))

    def mapped(self, params: LimbParams) -> dict[str, Any]:
        """``params`` (another value of the fit's parameters) through ``locate``'s body-centre mapping.

        Parameters
        ----------
        params : LimbParams
            Parameters of the fit's model, e.g. a posterior sample.

        Returns
        -------
        dict
            ``center_rc`` (body centre, (row, col) px), ``radius_px``, ``range_km`` and ``los`` (unit vector to the
            body centre, camera frame) as ``locate`` would report them for this fit (``None`` where not measured).
        """
        fit = eqx.tree_at(lambda f: f.params, self.final.fit, params)
        geo = self.body.body_center(self.frame, self.edge, dataclasses.replace(self.final, fit=fit))
        return {"center_rc": geo.center_rc, "radius_px": geo.radius_px, "range_km": geo.range_km, "los": geo.los}


def _stages(frame: Any, body: Any, cand: Any) -> tuple[Any, Any, Any]:
    """The edge fit, the final fit and its body-centre mapping (``locate``'s stages 3-6)."""
    pixels = body.limb_pixels(frame, cand)
    edge = body.edge_fit(frame, cand, pixels)
    extras = body.report(frame, cand, edge)
    final = body.refit(frame, cand, edge, extras)
    return edge, final, body.body_center(frame, edge, final)


def located_fit(image: Any, camera: Any = None, hints: Any = None, options: Any = None) -> LocatedFit:
    """``locate(image, camera, hints, options)`` and the final fit behind it (module docstring).

    Parameters
    ----------
    image, camera, hints, options
        As :func:`~jaxlimb.pipeline.locate`.

    Returns
    -------
    LocatedFit
        ``locate``'s measurement, the final fit, its body-centre mapping and covariance.

    Raises
    ------
    ConfigError
        The frame is measured by the whole-limb or visible-arc paths (a predicted limb, a disc larger
        than the frame), whose fits are not one limb-model fit; or the stages do not reproduce ``locate``.
    CheckFailed, ImageContentError, ...
        As :func:`~jaxlimb.pipeline.locate`.
    """
    m = locate(image, camera, hints, options)
    frame = prepare(image, camera, hints, options)
    body = body_strategy(frame)
    if isinstance(body, PredictedLimbSphere):
        raise ConfigError("this frame is measured on its whole (predicted) limb or its visible arc, not by one "
                          "limb-model fit: drop `expected_center_rc` from the hints")
    frame = body.prepare(frame)
    cand = body.candidates(frame)
    try:
        edge, final, geo = _stages(frame, body, cand)
    except InitialCircleOffError:
        edge, final, geo = _stages(frame, body, other_candidates(frame))
    off = float(np.max(np.abs(np.asarray(geo.center_rc) - np.asarray(m.center_rc))))
    if not off <= AGREEMENT_PX:
        raise ConfigError(f"the stages of locate gave another centre ({off:.3g} px away): cannot study its fit")
    cov = covariance(final, geo)
    return LocatedFit(m, final, geo, tuple(cov.names), np.asarray(cov.matrix), m.crlb, frame, body, edge)


def fit_problem(lf: LocatedFit, start_offset_px: float = 0.5) -> Any:
    """The fit ``locate`` ran as a :class:`~jaxlimb.analysis.problems.StudyProblem` (a parametric bootstrap of it).

    Parameters
    ----------
    lf : LocatedFit
        From :func:`located_fit`.
    start_offset_px : float
        Distance of the start's centre from the answer (px, split evenly over row and col); the size (``radius``
        or ``a``) starts off by the same.

    Returns
    -------
    StudyProblem
        The fit's model, pixels, weights and held parameters, the truth at its answer and the noise at its
        residual sigma.
    """
    from .problems import StudyProblem

    p = lf.params
    size = "a" if "a" in lf.model.param_names else "radius"
    d = start_offset_px / np.sqrt(2.0)
    init = p.replace(r0=float(p.r0) + d, c0=float(p.c0) - d, **{size: float(getattr(p, size)) + start_offset_px})
    w = None if lf.data.weights is None else np.asarray(lf.data.weights, float)
    return StudyProblem(lf.model, p, init, np.asarray(lf.data.coords, float), tuple(lf.final.fixed), lf.sigma, w,
                        label=f"locate's {lf.model.name} fit, {lf.data.coords.shape[0]} px, sigma {lf.sigma:.3g}")


__all__ = ["AGREEMENT_PX", "LocatedFit", "fit_problem", "located_fit", "model_of"]
