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
The values of the limb-pixel and edge-fit stages are defined in :mod:`jaxlimb.pipeline.edge_stages` and
re-exported here.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np

from ..errors import CheckFailed
from ..geometry.camera import Camera
from ..geometry.hints import Hints
from ..imaging.gradient_front_end import GradientOptions
from ..imaging.scanline_front_end import ScanlineOptions
from .edge_stages import (AnnulusSelection, EdgeFit, EllipsePixels, EllipsoidEdge, FitData, LimbPixels,
                          PredictedCandidates, PredictedEdge, PredictedPixels, RefineResult)
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
        """The options of front end ``name`` (default: the chosen one); ``None`` for its defaults.

        Parameters
        ----------
        name : str, optional
            ``"gradient"`` or ``"scanline"``.

        Returns
        -------
        GradientOptions, ScanlineOptions or None
            ``opt.gradient`` for the gradient front end, else ``opt.scanline``.
        """
        name = str(self.opt.front_end) if name is None else name
        return self.opt.gradient if name == "gradient" else self.opt.scanline

    def to_observed(self, rc_ideal) -> tuple[float, float]:
        """Ideal (pinhole) pixel -> observed pixel (through the lens distortion, if any).

        Parameters
        ----------
        rc_ideal : (float, float)
            Ideal pixel ``(row, col)``.

        Returns
        -------
        (float, float)
            Observed pixel ``(row, col)``.
        """
        if self.cam is not None and self.cam.has_distortion:
            return tuple(float(v) for v in self.cam.distort(np.asarray(rc_ideal, float)))
        return (float(rc_ideal[0]), float(rc_ideal[1]))

    def to_ideal(self, rc: np.ndarray) -> np.ndarray:
        """Observed pixels ``(n, 2)`` (or one) -> ideal pixels.

        Parameters
        ----------
        rc : np.ndarray (n, 2) or (2,)
            Observed pixels ``(row, col)``.

        Returns
        -------
        np.ndarray
            Same shape, ideal (pinhole) pixels.
        """
        if self.cam is not None and self.cam.has_distortion:
            return np.asarray(self.cam.undistort(np.asarray(rc, float)))
        return np.asarray(rc, float)

    def mark(self, stage: str) -> None:
        """Record the end of stage ``stage`` (``time.perf_counter``) in ``timings``.

        Parameters
        ----------
        stage : str
            Stage name (``front_end``, ``refine``, ``profile``, ``body_center`` ...).
        """
        self.timings[stage] = time.perf_counter()

    def phase(self, center_rc) -> float:
        """Phase angle (rad) at ``center_rc`` from the hints' Sun direction (Eq. 2 of Aerospace 2015).

        Parameters
        ----------
        center_rc : (float, float)
            Body centre ``(row, col)`` (px); its line of sight (the boresight without camera).

        Returns
        -------
        float
            Angle between the body-to-Sun and body-to-camera directions, in ``[0, pi]``.
        """
        assert self.hints is not None and self.hints.sun_dir_camera is not None
        s = np.asarray(self.hints.sun_dir_camera, dtype=float)
        s = s / np.linalg.norm(s)
        u = self.cam.los(np.asarray(center_rc, dtype=float)) if self.cam is not None else np.array([0.0, 0.0, 1.0])
        return float(np.arccos(np.clip(-s @ u, -1.0, 1.0)))


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
        """The matrix as the result's ``{name: {name: value}}`` (docs/design.md).

        Returns
        -------
        dict of str to dict of str to float
        """
        return {a: {b: float(self.matrix[i, j]) for j, b in enumerate(self.names)} for i, a in enumerate(self.names)}

    def block(self, names: tuple[str, ...]) -> np.ndarray:
        """The sub-matrix of the rows and columns ``names``.

        Parameters
        ----------
        names : tuple of str
            Row names, e.g. ``("center_r", "center_c")``.

        Returns
        -------
        np.ndarray (len(names), len(names))
        """
        idx = [self.names.index(n) for n in names]
        return self.matrix[np.ix_(idx, idx)]


@dataclass(frozen=True)
class Levels:
    """The edge in the units of the result: logistic ``k``, inside/outside levels (DN) and the PSF sigma;
    ``inside`` (DN): the fitted brightness inside the edge where the fit sees it, when the model's limb level
    ``ymax`` is not it (the interior ramp's, whose limb level may be ~0 under a rising interior), else ``None``."""

    k: float
    ymax: float
    ymin: float
    psf_sigma_px: float
    profile: dict[str, Any] | None
    inside: float | None = None


# =============================================================================== the strategies
PixelsT = TypeVar("PixelsT")
EdgeT = TypeVar("EdgeT")


class Body(ABC, Generic[PixelsT, EdgeT]):
    """A body strategy of :func:`~jaxlimb.pipeline.locate`: the stages that differ between bodies (module table).

    Abstract: every stage is implemented by a final strategy (sphere, disc, predicted-limb sphere, limb arc,
    ellipsoid, few-pixel); the stages they share are functions the strategies call, not methods they inherit.  One
    method has a default: :meth:`instead`, no other strategy for a refused frame.  ``name`` is
    what the checks call the body in their messages.
    """

    name: ClassVar[str]

    @abstractmethod
    def prepare(self, frame: Frame) -> Frame:
        """The frame as this body measures it (resampled, hints completed ...).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        Frame
        """

    @abstractmethod
    def candidates(self, frame: Frame) -> Any:
        """The limb candidates and the initial circle / ellipse (Checks 1-4).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.

        Returns
        -------
        Any
            The front end's answer (``LimbCandidates``, ``PredictedCandidates`` ...).
        """

    @abstractmethod
    def limb_pixels(self, frame: Frame, cand: Any) -> PixelsT:
        """Which pixels are the limb.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : Any
            The front end's answer (:meth:`candidates`).

        Returns
        -------
        PixelsT
        """

    @abstractmethod
    def edge_fit(self, frame: Frame, cand: Any, pixels: PixelsT) -> EdgeT:
        """The sigmoid edge fit and its checks.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : Any
            The front end's answer (:meth:`candidates`).
        pixels : PixelsT
            The limb pixels.

        Returns
        -------
        EdgeT
        """

    @abstractmethod
    def report(self, frame: Frame, cand: Any, edge: EdgeT) -> dict[str, Any]:
        """The intermediate values worth reporting (``extras``).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : Any
            The front end's answer (:meth:`candidates`).
        edge : EdgeT
            The edge fit (:meth:`edge_fit`).

        Returns
        -------
        dict of str to Any
        """

    @abstractmethod
    def refit(self, frame: Frame, cand: Any, edge: EdgeT, extras: dict[str, Any]) -> RefineResult:
        """The physical profile refit (or the edge fit with its model-error terms).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        cand : Any
            The front end's answer (:meth:`candidates`).
        edge : EdgeT
            The edge fit (:meth:`edge_fit`).
        extras : dict
            The report, which the refit may add to.

        Returns
        -------
        RefineResult
            The fit that answers.
        """

    @abstractmethod
    def body_center(self, frame: Frame, edge: EdgeT, final: RefineResult) -> BodyCenter:
        """Fitted limb -> body-centre image, radius / range, line of sight, with the map's Jacobian.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        edge : EdgeT
            The edge fit (:meth:`edge_fit`).
        final : RefineResult
            The answering fit.

        Returns
        -------
        BodyCenter
        """

    @abstractmethod
    def check(self, frame: Frame, levels: Levels, cov: Covariance) -> None:
        """Stage "checks": the fit is physical (levels, edge blur) and, where the body's covariance is the fit's, the
        centre within ``max_center_sigma_px``; a failure is a typed error.

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        levels : Levels
            The fitted edge.
        cov : Covariance
            The reported covariance.
        """

    @abstractmethod
    def iterations(self, edge: EdgeT, final: RefineResult) -> int:
        """The solver steps of the fits that made the answer.

        Parameters
        ----------
        edge : EdgeT
            The edge fit (:meth:`edge_fit`).
        final : RefineResult

        Returns
        -------
        int
        """

    def instead(self, frame: Frame, refusal: CheckFailed) -> "Body | None":
        """The strategy that measures the frame when this one refused it; ``None`` (every strategy but the sphere,
        which overrides it): the refusal stands.

        Parameters
        ----------
        frame : Frame
            The prepared inputs (before :meth:`prepare`).
        refusal : CheckFailed
            This strategy's refusal.

        Returns
        -------
        Body or None
        """
        return None

    @abstractmethod
    def finish(self, frame: Frame, meas: LimbMeasurement) -> LimbMeasurement:
        """The body's last check or map of the measurement (dark limb, lens distortion ...).

        Parameters
        ----------
        frame : Frame
            The prepared inputs.
        meas : LimbMeasurement

        Returns
        -------
        LimbMeasurement
        """


__all__ = ["AnnulusSelection", "Body", "BodyCenter", "Covariance", "EdgeFit", "EllipsePixels", "EllipsoidEdge", "FitData",
           "Frame", "LimbPixels", "Levels", "PredictedCandidates", "PredictedEdge",
           "PredictedPixels", "RefineResult"]
