"""The measurement a limb pipeline returns (Moon, Earth, Sun...), and its JSON form (docs/design.md contract)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: The names of the body centre's image in every covariance ``locate`` reports.
CENTER_NAMES = ("center_r", "center_c")


def covariance_block(cov: Mapping[str, Mapping[str, float]], names: Sequence[str] = CENTER_NAMES) -> np.ndarray:
    """The covariance of ``names`` as an array, from the nested ``{name: {name: value}}`` form of
    :attr:`LimbMeasurement.covariance` (and of the result JSON).

    Parameters
    ----------
    cov : mapping
        ``{name: {name: value}}``.
    names : sequence of str
        The parameters, in the array's order; default the body centre's image ``(center_r, center_c)`` (px^2).

    Returns
    -------
    numpy.ndarray
        ``(len(names), len(names))``.
    """
    return np.array([[float(cov[a][b]) for b in names] for a in names])


@dataclass(frozen=True)
class EllipseResult:
    """An image ellipse: centre ``(row, col)``, semi-axes ``(a, b)`` with ``a >= b`` (px), and angle.

    ``angle_rad`` is the direction of the ``a`` axis measured from ``+col`` toward
    ``-row`` (counter-clockwise as displayed): the axis direction is
    ``(d_row, d_col) = (-sin(angle), cos(angle))`` -- the convention of
    :func:`jaxlimb.models.ellipse_coords` and of the renderer's truth.
    """

    center_rc: tuple[float, float]
    semi_axes_px: tuple[float, float]
    angle_rad: float

    def to_json(self) -> dict[str, Any]:
        """The ellipse as the ``"ellipse"`` object of the result JSON (docs/design.md).

        Returns
        -------
        dict
            ``center_rc`` ``[r, c]``, ``semi_axes_px`` ``[a, b]``, ``angle_rad``.
        """
        return {"center_rc": list(self.center_rc), "semi_axes_px": list(self.semi_axes_px), "angle_rad": self.angle_rad}


@dataclass(frozen=True)
class LimbMeasurement:
    """What ``locate`` measures.

    Attributes
    ----------
    center_rc : the image of the **body centre** ``(row, col)`` (after any offset correction).
    radius_px : apparent radius of the fitted circle (circle model), else ``None``.
    ellipse : the fitted image ellipse (ellipse model), else ``None``.
    k, ymax, ymin : the sigmoid's steepness and levels.
    covariance : ``{name: {name: value}}`` of the estimated parameters (``center_r``,
        ``center_c`` for the body centre, ``radius``/``a``..., ``k``...), from
        :math:`\\hat\\sigma^2 (J^\\top J)^{-1}` propagated to the body centre.
    iterations, solver, front_end, n_pixels : how it was obtained.
    los_camera : unit line of sight to the body centre in the camera frame (camera known).
    range_km : range to the body centre (camera and body size known).
    crlb : Cramér--Rao bound ``{name: sigma}`` where computed.
    covariance_noise : the same bound with its correlations, ``{name: {name: value}}`` over ``covariance``'s names:
        the noise-only part of ``covariance`` (what is left is the model-error terms).
    extras : anything else worth reporting (initial estimate, checks passed, timings).
    selected_pixels_rc : ``(n, 2)`` pixels ``(row, col)`` used by the final fit (for figures;
        ``None`` if not kept).  Not part of :meth:`to_json`.
    """

    center_rc: tuple[float, float]
    radius_px: float | None
    ellipse: EllipseResult | None
    k: float
    ymax: float
    ymin: float
    covariance: dict[str, dict[str, float]]
    iterations: int
    solver: str
    front_end: str
    n_pixels: int
    los_camera: tuple[float, float, float] | None = None
    range_km: float | None = None
    crlb: dict[str, float] | None = None
    covariance_noise: dict[str, dict[str, float]] | None = None
    extras: dict[str, Any] = field(default_factory=dict)
    selected_pixels_rc: Any = field(default=None, repr=False, compare=False)

    @property
    def center_covariance(self) -> np.ndarray:
        """The ``2 x 2`` covariance (px^2) of ``center_rc`` (:func:`covariance_block`)."""
        return covariance_block(self.covariance)

    def to_json(self) -> dict[str, Any]:
        """The ``--json`` success object of ``jaxlimb locate`` (docs/design.md).

        Returns
        -------
        dict
            ``status`` ``"ok"``, ``center_rc`` and the other fields; the optional ones (``radius_px``, ``ellipse``,
            ``los_camera``, ``range_km``, ``crlb``, ``covariance_noise``, ``extras``) only when set; never ``selected_pixels_rc``.

        Raises
        ------
        ValueError
            A non-finite number anywhere in it (the JSON carries no NaN or inf).
        """
        out: dict[str, Any] = {"status": "ok", "center_rc": [float(v) for v in self.center_rc]}
        if self.radius_px is not None:
            out["radius_px"] = float(self.radius_px)
        if self.ellipse is not None:
            out["ellipse"] = self.ellipse.to_json()
        out.update(
            k=float(self.k), ymax=float(self.ymax), ymin=float(self.ymin),
            covariance=self.covariance, iterations=int(self.iterations), solver=self.solver,
            front_end=self.front_end, n_pixels=int(self.n_pixels),
        )
        if self.los_camera is not None:
            out["los_camera"] = [float(v) for v in self.los_camera]
        if self.range_km is not None:
            out["range_km"] = float(self.range_km)
        if self.crlb is not None:
            out["crlb"] = self.crlb
        if self.covariance_noise is not None:
            out["covariance_noise"] = self.covariance_noise
        if self.extras:
            out["extras"] = self.extras
        _check_finite(out)
        return out


def _check_finite(obj: Any, path: str = "") -> None:
    """JSON output must not carry NaN/inf (``allow_nan=False``): fail loudly, not silently."""
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"non-finite value in measurement at {path or 'top level'}")
    if isinstance(obj, dict):
        for k, v in obj.items():
            _check_finite(v, f"{path}.{k}" if path else str(k))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _check_finite(v, f"{path}[{i}]")
