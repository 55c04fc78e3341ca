r"""The stages of :func:`jaxlimb.pipeline.locate` and the typed values they pass on; the abstract body strategy.

=====================  ==========================================================  =====================
stage                  what                                                        value
=====================  ==========================================================  =====================
prepare                validate image / camera / hints / options; Check 1 on the   :class:`Frame`
                       prior from the hints (Aerospace 2015 §3)
candidates             front end (``gradient`` or ``scanline``; the predicted      front-end candidates
                       limb with a SPICE prediction), Checks 1-4
limb pixels            the lit limb's pixels (annulus / band, lit-side window)     :class:`LimbPixels`,
                                                                                   :class:`EllipsePixels`,
                                                                                   :class:`PredictedPixels`
edge fit               sigmoid edge (CSF, Eq. 16; ESF with ramp for an ellipsoid);  :class:`EdgeFit`,
                       Checks 3 (outliers), 5 (convergence, jump), 1, 4, lit arc   :class:`EllipsoidEdge`,
                                                                                   :class:`PredictedEdge`
profile refit          lunar-Lambert limb profile; limb-darkened disc (Sun)        :class:`RefineResult`
body-centre mapping    limb -> body-centre image, radius / range, LOS              :class:`BodyCenter`
covariance             :math:`\hat\sigma^2 (J^\top J)^{-1}` through the map      :class:`Covariance`
checks                 levels, edge blur, centre sigma                             :class:`Levels`
result                 the same measurement for every body                         ``LimbMeasurement``
=====================  ==========================================================  =====================

A body strategy (:class:`Body`) supplies the stages that differ between bodies; every strategy is a final class
(:mod:`jaxlimb.pipeline.sphere`, :mod:`jaxlimb.pipeline.ellipsoid`), chosen by :func:`jaxlimb.pipeline.bodies.body_strategy`.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Generic, TypeVar

import equinox as eqx
import jax
import numpy as np

from ..fitting import LimbFit
from ..geometry.camera import Camera
from ..geometry.hints import Hints
from ..geometry.sphere_image import SphereImage
from ..imaging.gradient_front_end import GradientOptions
from ..imaging.predicted import LimbShape
from ..imaging.scanline_front_end import ScanlineOptions
from .options import LocateOptions
from .result import EllipseResult, LimbMeasurement


# =============================================================================== prepare
@dataclass(frozen=True)
class Frame:
    """The validated inputs of one measurement.

    Attributes
    ----------
    img : the grey image (float or integer array, 2-D).
    cam : the camera or ``None``; ``pin`` its pinhole part (no distortion).
    hints, opt : the hints (or ``None``) and the options.
    t0 : start time (``time.perf_counter``) for the timings.
    timings : stage name -> end time, filled in as the stages run.
    observed_cam : the camera of the observed image when a strategy resampled it onto the ideal grid
        (``img``/``cam`` are then the resampled image and its pinhole camera).
    mask : validity mask (``True`` = measured pixel) or ``None``; the gradient front end drops
        candidates near invalid pixels.
    """

    img: np.ndarray
    cam: Camera | None
    hints: Hints | None
    opt: LocateOptions
    t0: float
    timings: dict[str, float] = field(default_factory=dict)
    observed_cam: Camera | None = None
    mask: np.ndarray | None = None

    @property
    def pin(self) -> Camera | None:
        c = self.cam
        return None if c is None else Camera(c.focal_length_mm, c.pixel_pitch_mm, c.rows, c.cols, c.principal_point_rc)

    @property
    def use_camera(self) -> bool:
        """The body-centre correction applies (a camera, and the option on)."""
        return self.cam is not None and self.opt.body_center_correction

    @property
    def sun_known(self) -> bool:
        return self.hints is not None and self.hints.sun_dir_camera is not None

    @property
    def body_radius_km(self) -> float | None:
        return self.hints.radius_km() if self.hints is not None else None

    def front_end_options(self, name: str | None = None) -> GradientOptions | ScanlineOptions | None:
        """The options of front end ``name`` (default: the chosen one); ``None`` for its defaults."""
        name = str(self.opt.front_end) if name is None else name
        return self.opt.gradient if name == "gradient" else self.opt.scanline

    def to_observed(self, rc_ideal) -> tuple[float, float]:
        """Ideal (pinhole) pixel -> observed pixel (through the lens distortion, if any)."""
        if self.cam is not None and self.cam.has_distortion:
            return tuple(float(v) for v in self.cam.distort(np.asarray(rc_ideal, float)))
        return (float(rc_ideal[0]), float(rc_ideal[1]))

    def to_ideal(self, rc: np.ndarray) -> np.ndarray:
        """Observed pixels ``(n, 2)`` (or one) -> ideal pixels."""
        if self.cam is not None and self.cam.has_distortion:
            return np.asarray(self.cam.undistort(np.asarray(rc, float)))
        return np.asarray(rc, float)

    def mark(self, stage: str) -> None:
        self.timings[stage] = time.perf_counter()

    def phase(self, center_rc) -> float:
        """Phase angle (rad) at ``center_rc`` from the hints' Sun direction (Eq. 2 of Aerospace 2015)."""
        assert self.hints is not None and self.hints.sun_dir_camera is not None
        s = np.asarray(self.hints.sun_dir_camera, dtype=float)
        s = s / np.linalg.norm(s)
        u = self.cam.los(np.asarray(center_rc, dtype=float)) if self.cam is not None else np.array([0.0, 0.0, 1.0])
        return float(np.arccos(np.clip(-s @ u, -1.0, 1.0)))


# =============================================================================== limb pixels, edge fit
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
        """Polar angles ``atan2(d_row, d_col)`` of the pixels about ``center_rc``."""
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
        return FitData(self.coords[keep], self.z[keep], None if self.weights is None else self.weights[keep],
                       self.offset, self.scale)

    def with_coords(self, coords: np.ndarray) -> FitData:
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
        ``noise_covariance`` it widened): the one setter of the model-error terms."""
        return replace(self, fit=eqx.tree_at(lambda x: x.covariance, self.fit, C if isinstance(C, jax.Array) else jax.device_put(np.asarray(C))), **changes)

    def with_move_witness(self, other: "RefineResult", frac: float) -> "RefineResult":
        """A copy with ``(frac |d|)^2`` added to the variances of ``r0`` and ``c0`` and ``(frac d_a)^2`` to that of
        ``a``, ``d`` the move of ``(r0, c0, a)`` from ``other`` (a second model of the same limb whose correction is
        itself uncertain, in every direction); unchanged unless all three are free."""
        free = list(self.fit.free)
        if not all(n in free for n in ("r0", "c0", "a")):
            return self
        d = np.array([float(getattr(self.fit.params, n)) - float(getattr(other.fit.params, n)) for n in ("r0", "c0", "a")])
        C = np.array(self.fit.covariance)
        for i, v in zip((free.index("r0"), free.index("c0"), free.index("a")),
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
    """The edge fit of a round limb: the circular sigmoid on the final annulus, and how it was reached."""

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
        return float(self.circ.fit.params.radius)


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



# =============================================================================== body centre, covariance, levels
@dataclass(frozen=True)
class BodyCenter:
    """The body-centre mapping of one fit.

    Attributes
    ----------
    center_rc, radius_px, ellipse, los, range_km : the reported geometry (``None`` where not measured).
    outputs : names of the mapped quantities (``center_r``, ``center_c``, ``radius`` / ``range_km`` ...).
    params : the fit parameters they are a function of (names of the fit's free parameters).
    jacobian : ``(len(outputs), len(params))`` derivative of the map at the estimate.
    model_cov : optional ``(len(outputs),)*2`` covariance of a model error added to the mapped block
        (the unsigned centre offset of a free ellipse, :mod:`jaxlimb.pipeline.ellipsoid`).
    extras : numbers worth reporting (the limb ellipse ...).
    """

    center_rc: tuple[float, float]
    radius_px: float | None
    ellipse: EllipseResult | None
    los: tuple[float, float, float] | None
    range_km: float | None
    outputs: tuple[str, ...]
    params: tuple[str, ...]
    jacobian: np.ndarray
    model_cov: np.ndarray | None = None
    extras: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Covariance:
    """A square covariance and the names of its rows (and the Jacobian from the fit's free parameters)."""

    names: list[str]
    matrix: np.ndarray
    jacobian: np.ndarray

    def as_dict(self) -> dict[str, dict[str, float]]:
        return {a: {b: float(self.matrix[i, j]) for j, b in enumerate(self.names)} for i, a in enumerate(self.names)}

    def block(self, names: tuple[str, ...]) -> np.ndarray:
        idx = [self.names.index(n) for n in names]
        return self.matrix[np.ix_(idx, idx)]


@dataclass(frozen=True)
class Levels:
    """The edge in the units of the result: logistic ``k``, inside/outside levels (DN) and the PSF sigma."""

    k: float
    ymax: float
    ymin: float
    psf_sigma_px: float
    profile: dict[str, Any] | None


# =============================================================================== the strategies
PixelsT = TypeVar("PixelsT")
EdgeT = TypeVar("EdgeT")


class Body(ABC, Generic[PixelsT, EdgeT]):
    """A body strategy of :func:`~jaxlimb.pipeline.locate`: the stages that differ between bodies (module table).

    Abstract: every stage is implemented by a final strategy (sphere, disc, predicted-limb sphere, limb arc,
    ellipsoid); the stages they share are functions the strategies call, not methods they inherit.  ``name`` is
    what the checks call the body in their messages.
    """

    name: ClassVar[str]

    @abstractmethod
    def prepare(self, frame: Frame) -> Frame:
        """The frame as this body measures it (resampled, hints completed ...)."""

    @abstractmethod
    def candidates(self, frame: Frame) -> Any:
        """The limb candidates and the initial circle / ellipse (Checks 1-4)."""

    @abstractmethod
    def limb_pixels(self, frame: Frame, cand: Any) -> PixelsT:
        """Which pixels are the limb."""

    @abstractmethod
    def edge_fit(self, frame: Frame, cand: Any, pixels: PixelsT) -> EdgeT:
        """The sigmoid edge fit and its checks."""

    @abstractmethod
    def report(self, frame: Frame, cand: Any, edge: EdgeT) -> dict[str, Any]:
        """The intermediate values worth reporting (``extras``)."""

    @abstractmethod
    def refit(self, frame: Frame, cand: Any, edge: EdgeT, extras: dict[str, Any]) -> RefineResult:
        """The physical profile refit (or the edge fit with its model-error terms)."""

    @abstractmethod
    def body_center(self, frame: Frame, edge: EdgeT, final: RefineResult) -> BodyCenter:
        """Fitted limb -> body-centre image, radius / range, line of sight, with the map's Jacobian."""

    @abstractmethod
    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        """Stage "checks": the fit is physical (levels, edge blur) and, where the body's covariance is the fit's, the
        centre within ``max_center_sigma_px``; a failure is a typed error."""

    @abstractmethod
    def iterations(self, edge: EdgeT, final: RefineResult) -> int:
        """The solver steps of the fits that made the answer."""

    @abstractmethod
    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """The body's last check or map of the measurement (dark limb, lens distortion ...)."""


__all__ = ["AnnulusSelection", "Body", "BodyCenter", "Covariance", "EdgeFit", "EllipsePixels", "EllipsoidEdge", "FitData",
           "Frame", "LimbPixels", "Levels", "PredictedCandidates", "PredictedEdge",
           "PredictedPixels", "RefineResult"]
