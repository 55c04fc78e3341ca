r"""The typed values of the limb-pixel and edge-fit stages of :func:`jaxlimb.pipeline.locate` (the table of
:mod:`jaxlimb.pipeline.stages`, which re-exports them): the selected pixels, the data and result of a sigmoid fit,
and each body strategy's limb pixels and edge fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import equinox as eqx
import jax
import numpy as np

from ..fitting import LimbFit
from ..geometry.sphere_image import SphereImage
from ..imaging.predicted import LimbShape
from ..models import CircleParams


@dataclass(frozen=True)
class AnnulusSelection:
    """The pixels selected for the sigmoid fit.

    Attributes
    ----------
    coords : ``(n, 2)`` pixel coordinates ``(row, col)``.
    z : ``(n,)`` intensities.
    center_rc, radius : the circle the annulus is built on.
    dr : the half-width (px).
    direction : unit ``(d_row, d_col)`` of the middle of the selected arc, or ``None`` (whole circle).
    halfangle : half-angle of the geometric window (rad; ``pi`` = whole circle).
    inner_level, outer_level : medians of the inner and outer quarters (initial ``ymax``, ``ymin``).
    inner_edge_mean, outer_edge_mean : means of the pixels within 1 px of ``r - dr`` and ``r + dr``
        (the fixed levels of the illuminated-ellipsoid paper §VI).
    n_bins_kept, n_bins : angular bins kept by the contrast test, and bins with pixels.
    pixel_inner, pixel_outer : ``(n,)`` the inner and outer levels (medians of the inner and
        outer quarters) of each pixel's angular bin, for the level normalisation.
    """

    coords: np.ndarray
    z: np.ndarray
    center_rc: tuple[float, float]
    radius: float
    dr: float
    direction: tuple[float, float] | None
    halfangle: float
    inner_level: float
    outer_level: float
    inner_edge_mean: float
    outer_edge_mean: float
    n_bins_kept: int
    n_bins: int
    pixel_inner: np.ndarray | None = None
    pixel_outer: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.z.shape[0])

    def angles(self) -> np.ndarray:
        """Polar angles ``atan2(d_row, d_col)`` of the pixels about ``center_rc``.

        Returns
        -------
        np.ndarray (n,)
            Radians, in ``(-pi, pi]``.
        """
        return np.arctan2(self.coords[:, 0] - self.center_rc[0], self.coords[:, 1] - self.center_rc[1])


@dataclass(frozen=True)
class FitData:
    """The data of a sigmoid fit: pixels, (normalised) intensities, weights and the DN scale.

    Level-normalised (the round limb's annulus, :func:`jaxlimb.pipeline.sphere.fits.fit_data`), each pixel is
    divided by its angular bin's contrast, ``z_n = (z - O_bin) / (I_bin - O_bin)`` and weighted by ``w = (I_bin - O_bin) / C_ref``
    (``C_ref`` the median contrast), so that the weighted residuals are the DN residuals
    divided by ``C_ref``: the fit is the CSF with an angle-dependent amplitude, i.e. the
    lit limb's brightness may vary along the arc (it does: Lambert-like surfaces fade
    toward the horns as the cosine of the angle from the sub-solar limb point, which pulls
    a one-level CSF inward there by px).  ``offset``/``scale`` map fitted levels back to
    DN: ``DN = offset + scale * y``.
    """

    coords: np.ndarray
    z: np.ndarray
    weights: np.ndarray | None
    offset: float
    scale: float

    def subset(self, keep: np.ndarray) -> FitData:
        """The pixels ``keep`` of the data (same offset and scale).

        Parameters
        ----------
        keep : np.ndarray
            Boolean mask ``(n,)`` or indices.

        Returns
        -------
        FitData
        """
        return FitData(self.coords[keep], self.z[keep], None if self.weights is None else self.weights[keep],
                       self.offset, self.scale)

    def with_coords(self, coords: np.ndarray) -> FitData:
        """The same data at other coordinates (e.g. undistorted pixels).

        Parameters
        ----------
        coords : np.ndarray (n, 2)
            Pixels ``(row, col)``.

        Returns
        -------
        FitData
        """
        return FitData(coords, self.z, self.weights, self.offset, self.scale)


@dataclass(frozen=True)
class RefineResult:
    r"""A sigmoid fit on an annulus, after the outlier pass.

    Attributes
    ----------
    fit : the final :class:`~jaxlimb.fitting.LimbFit`.
    data : the :class:`FitData` of the final fit (outliers removed; ideal pixel coordinates
        for the sphere fit of a camera with distortion).
    n_outliers : pixels dropped by the residual test.
    fixed : names of the parameters held fixed.
    sphere : for :func:`fit_sphere_annulus`, the :class:`~jaxlimb.geometry.sphere_image.SphereImage`
        of the final estimate.
    noise_covariance : the fit's noise-only covariance :math:`\hat\sigma^2 (J^\top J)^{-1}` when
        ``fit.covariance`` carries a model-error term (:func:`jaxlimb.pipeline.profile.model_error.with_model_error`);
        ``None``: ``fit.covariance`` is noise-only.  The Cramér--Rao bound uses this one.
    """

    fit: LimbFit
    data: FitData
    n_outliers: int
    fixed: tuple[str, ...]
    sphere: SphereImage | None = None
    noise_covariance: np.ndarray | None = None

    @property
    def coords(self) -> np.ndarray:
        return self.data.coords

    @property
    def covariance_noise(self) -> np.ndarray:
        """The noise-only covariance of the free parameters (see ``noise_covariance``)."""
        return np.asarray(self.fit.covariance if self.noise_covariance is None else self.noise_covariance)

    def with_covariance(self, C: np.ndarray, **changes) -> "RefineResult":
        """A copy whose fit's covariance is ``C`` (and whose other fields are ``changes``, e.g. the
        ``noise_covariance`` it widened): the one setter of the model-error terms.

        Parameters
        ----------
        C : np.ndarray (p, p)
            Covariance over the fit's free parameters.
        **changes
            Other fields of the copy.

        Returns
        -------
        RefineResult
        """
        cov = C if isinstance(C, jax.Array) else jax.device_put(np.asarray(C))  # no program compiled per process
        return replace(self, fit=eqx.tree_at(lambda x: x.covariance, self.fit, cov), **changes)

    def with_move_witness(self, other: "RefineResult", frac: float) -> "RefineResult":
        """A copy with ``(frac |d|)^2`` added to the variances of ``r0`` and ``c0`` and ``(frac d_a)^2`` to that of
        the size, ``d`` the move of ``(r0, c0, size)`` from ``other`` (a second model of the same limb whose correction
        is itself uncertain, in every direction); the size is ``a`` (profile, ellipse) or ``radius`` (circle) of each
        fit; unchanged unless all three are free.

        Parameters
        ----------
        other : RefineResult
            The other model's fit of the same limb.
        frac : float
            Fraction of the move taken as its 1-sigma.

        Returns
        -------
        RefineResult
        """
        free = list(self.fit.free)
        mine, theirs = (("r0", "c0", "radius" if isinstance(p, CircleParams) else "a") for p in (self.fit.params,
                                                                                                 other.fit.params))
        if not all(n in free for n in mine):
            return self
        d = np.array([float(getattr(self.fit.params, a)) - float(getattr(other.fit.params, b))
                      for a, b in zip(mine, theirs)])
        C = np.array(self.fit.covariance)
        for i, v in zip([free.index(n) for n in mine],
                        (float(np.hypot(d[0], d[1])),) * 2 + (abs(d[2]),)):
            C[i, i] += (frac * v) ** 2
        return self.with_covariance(C)


@dataclass(frozen=True)
class LimbPixels:
    """The pixels of the lit limb: the annulus and the lit-side window it was cut with.

    ``direction`` (unit ``(d_row, d_col)`` toward the lit side, ``None``: all round) and ``half``
    (rad) the window; ``phase`` (rad) the phase angle used (``None``: unknown); ``dr`` the annulus
    half-width (px); ``min_arc_deg`` the shortest lit arc accepted; ``dr_max`` the widest half-width the
    edge fit may widen it to; ``shift`` (px) how far the annulus' middle lies outside the circle (a thin
    crescent's band: :func:`crescent_halfwidth`, :func:`limb_pixels`).
    """

    sel: AnnulusSelection
    dr: float
    direction: tuple[float, float] | None
    half: float
    phase: float | None
    min_arc_deg: float
    dr_max: float = math.inf
    shift: float = 0.0


@dataclass(frozen=True)
class EdgeFit:
    """The edge fit of a round limb: the circular sigmoid on the final annulus (on an EUV disc, the corona's limb,
    :func:`~jaxlimb.pipeline.sphere.corona.corona_edge`), and how it was reached."""

    circ: RefineResult
    pixels: LimbPixels
    widened: bool
    recentered: bool
    arc_deg: float
    jump_px: float = 0.0
    jump_limit_px: float = 0.0

    @property
    def center_rc(self) -> tuple[float, float]:
        p = self.circ.fit.params
        return (float(p.r0), float(p.c0))

    @property
    def radius(self) -> float:
        p = self.circ.fit.params
        return float(p.radius if isinstance(p, CircleParams) else p.a)


@dataclass(frozen=True)
class EllipsePixels:
    """The start of the ellipsoid's edge fit: position prior, lit window and initial ellipse."""

    p0: np.ndarray
    range_prior_km: float
    lit_dir: tuple[float, float] | None
    half: float
    ellipse: tuple
    trace: Any = None
    ray_fit: bool = False

    @property
    def patchy(self) -> bool:
        """An albedo-patchy lit limb (:meth:`~jaxlimb.pipeline.ellipsoid.trace.TracedLimb.patchy`): the band is then
        level-normalised per ray and the edge is a plain step (no ramp, no profile refit)."""
        return self.trace is not None and self.trace.patchy()


@dataclass(frozen=True)
class EllipsoidEdge:
    """The ellipsoid's edge fit: the last fit, its pixels, ellipse ``((r0, c0), (a, b), theta)``, position; on a
    patchy limb also the other estimate's ``(r0, c0, a)`` (``witness``, :func:`_patchy_geometry`) and whether the
    band fit converged."""

    final: RefineResult
    pixels: EllipsePixels
    fitted: tuple
    p: np.ndarray
    history: list
    jump_px: float
    jump_limit_px: float
    witness: tuple | None = None
    band_converged: bool = True
    shading_shift: tuple | None = None
    asymmetry: tuple | None = None

    @property
    def n_steps(self) -> int:
        return int(sum(h["fit_steps"] for h in self.history))

@dataclass(frozen=True)
class PredictedCandidates:
    """The predicted-limb front end's answer (:mod:`jaxlimb.imaging.predicted`): the limb the hints predict, the edge
    points found along it (either polarity; ``step`` their sign and size, ``used`` those the shape fit kept), the
    predicted shape fitted to them, and the image noise."""

    predicted: LimbShape
    points_rc: np.ndarray
    step: np.ndarray
    used: np.ndarray
    shape: LimbShape
    noise: float
    front_end: str = "predicted"
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class PredictedPixels:
    """The whole limb's first annulus: ``|d| <= dr`` px about ``shape`` (re-drawn about each fit)."""

    shape: LimbShape
    dr: float


@dataclass(frozen=True)
class PredictedEdge:
    """The whole-limb edge fit: the last pass's fit, the fitted limb (predicted shape, measured place and scale), the
    last annulus half-width, the angular bins with a limb step of either polarity, the centre's gains per px of
    three edge-error patterns along the arc (:func:`~jaxlimb.imaging.predicted.edge_bias_gain`), the predicted limb
    and the image noise."""

    fit: RefineResult
    shape: LimbShape
    dr: float
    counts: dict[str, int]
    gain: np.ndarray
    predicted: LimbShape
    noise: float


__all__ = ["AnnulusSelection", "EdgeFit", "EllipsePixels", "EllipsoidEdge", "FitData", "LimbPixels", "PredictedCandidates",
           "PredictedEdge", "PredictedPixels", "RefineResult"]
