"""The standard problems of the noise studies: one rendered limb per model, with its truth, start and pixels.

Every limb model of :mod:`jaxlimb.models` has one: the three sigmoids of Sec. V of Mortari, D'Souza &
Zanetti 2016 (``linear``, ``circle``, ``ellipse``), the elliptical ramp (``ellipse_ramp``), the lunar-Lambert
limb profile (``lunar_limb``) and the limb-darkened disc (``limb_darkened``).  The intensities are the model
itself (the Cramér--Rao bound applies to every realisation), the pixels a band of ``annulus`` px around the
limb of the *start* (one pixel set for every realisation), the start ``start_offset_px`` off in the centre and
the size, the other parameters at the truth.  The circular sigmoid's problem (radius 150 px, k = 3, 200/20 DN,
sigma 10 DN, +-6 px: ~11 000 pixels) is the package's standard problem (``benchmarks/solvers.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np

from ..errors import LimbInputError
from ..models import (CIRCLE, ELLIPSE, ELLIPSE_RAMP, LIMB_DARKENED, LIMB_PROFILE, LINEAR, PROFILE_FIXED, CircleParams,
                      EllipseParams, EllipseRampParams, LimbDarkenedParams, LimbModel, LimbParams, LimbProfileParams,
                      LinearParams, lunar_lambert_slope, lunar_lambert_weight)

#: The models of :func:`standard_problem`, by name.
STUDY_MODELS = ("linear", "circle", "ellipse", "ellipse_ramp", "lunar_limb", "limb_darkened")
#: Parameters each problem holds at the truth besides the user's ``fixed``.
ALWAYS_FIXED = {"ellipse": ("rho",), "ellipse_ramp": ("rho", "theta", "h3", "h4"),
                "lunar_limb": tuple(n for n in PROFILE_FIXED if n != "L"), "limb_darkened": ("u2",)}
_MOON_RANGE_KM, _MOON_RADIUS_KM, _PHASE_DEG, _PSF_PX = 150_000.0, 1737.4, 45.0, 0.8


@dataclass(frozen=True)
class ModelStudyOptions:
    """Settings of a model-only study (defaults: the standard problem, module docstring)."""

    model: str = "circle"
    """One of :data:`STUDY_MODELS`."""
    shape: tuple[int, int] = (400, 400)
    """Image size (rows, cols)."""
    radius: float = 150.0
    """Radius (circle, profile, disc) or semi-axis ``a`` (ellipse, ramp), px; the linear edge's column."""
    rho: float = 0.9
    """Axis ratio of the ellipse and the ramp (held fixed in the fit)."""
    theta: float = 0.3
    """Orientation of the ellipse, rad."""
    k: float = 3.0
    """Sigmoid steepness (the ramp's Gaussian kernel is ``1/k``; the physical profiles use a 0.8 px PSF)."""
    ymax: float = 200.0
    ymin: float = 20.0
    sigma: float = 10.0
    """Gaussian noise, DN."""
    annulus: float = 6.0
    """Half-width of the selected band around the initial limb, px."""
    start_offset_px: float = 0.5
    """Distance of the initial centre from the truth (the radius starts off by the same)."""
    n: int = 1000
    seed: int = 0
    batch: int = 250
    """Realisations per compiled batch."""
    fixed: tuple[str, ...] = field(default=())
    """Parameters held at their true values (with :data:`ALWAYS_FIXED`)."""

    def __post_init__(self) -> None:
        if self.model not in STUDY_MODELS:
            raise LimbInputError(f"`model` must be one of {list(STUDY_MODELS)}, got {self.model!r}")
        from .._validate import POSITIVE, Range, number

        for name in ("radius", "k", "sigma", "annulus"):
            number(getattr(self, name), f"`{name}`", POSITIVE, error=LimbInputError)
        number(self.n, "`n`", Range(2, None), integer=True, error=LimbInputError)
        number(self.batch, "`batch`", Range(1, None), integer=True, error=LimbInputError)
        number(self.seed, "`seed`", Range(0, 2**32 - 1), integer=True, error=LimbInputError)
        names = _MODELS[self.model].param_names
        unknown = sorted(set(self.fixed) - set(names))
        if unknown:
            raise LimbInputError(f"`fixed` (--fix) names unknown parameters {unknown}; the {self.model} model has {list(names)}")
        if not set(names) - set(self.fixed) - set(ALWAYS_FIXED.get(self.model, ())):
            raise LimbInputError(f"`fixed` (--fix) holds every parameter of the {self.model} model: nothing to estimate")


_MODELS: dict[str, LimbModel] = {"linear": LINEAR, "circle": CIRCLE, "ellipse": ELLIPSE, "ellipse_ramp": ELLIPSE_RAMP,
                                 "lunar_limb": LIMB_PROFILE, "limb_darkened": LIMB_DARKENED}


@dataclass(frozen=True)
class StudyProblem:
    """One fixed pixel set of a limb, the model's truth and the start of every fit.

    ``weights``: per-pixel weights of the fit (``None``: all 1); ``sigma``: the noise of the realisations (DN).
    """

    model: LimbModel
    truth: LimbParams
    init: LimbParams
    coords: np.ndarray
    fixed: tuple[str, ...]
    sigma: float
    weights: np.ndarray | None = None
    label: str = ""

    @property
    def clean(self) -> np.ndarray:
        """The noise-free intensities of the pixels (the model at the truth)."""
        return np.asarray(self.model.intensity(self.truth, jnp.asarray(self.coords)))

    @property
    def noise_scale(self) -> np.ndarray:
        """The noise sigma of each pixel (DN): ``sigma / w`` (a weight is ``1/sigma_i`` in units of ``sigma``)."""
        w = np.ones(self.coords.shape[0]) if self.weights is None else np.asarray(self.weights, float)
        return self.sigma / np.where(w > 0, w, 1.0)

    @property
    def free(self) -> tuple[str, ...]:
        return tuple(self.model.param_names[i] for i in self.model.free_indices(self.fixed))


def estimated_nbytes(opt: ModelStudyOptions) -> float:
    """Peak memory (bytes) of a study of ``opt``, estimated before running it.

    The pixel grid of :func:`standard_problem` (about six float64 images) and the fit of one realisation (the
    compiled program maps over a batch one member at a time: data, residuals and the Jacobian of the
    ``2 pi radius x 2 annulus`` band pixels, padded to the next bucket, x4 for the solver's temporaries; x20
    quadrature nodes for the physical profiles).

    Parameters
    ----------
    opt : ModelStudyOptions
        The study (model, image shape, radius, annulus, batch).

    Returns
    -------
    float
        Estimated peak memory in bytes.
    """
    rows, cols = opt.shape
    n_pix = 1.5 * 2.0 * math.pi * opt.radius * 2.0 * opt.annulus
    n_par = len(_MODELS[opt.model].param_names)
    nodes = 20.0 if opt.model in ("lunar_limb", "limb_darkened") else 1.0
    return 8.0 * (6.0 * rows * cols + 4.0 * n_pix * (n_par + 6) * nodes + 2.0 * opt.batch * n_par)


def _centre(opt: ModelStudyOptions) -> tuple[float, float, float]:
    """The true centre (near the image centre, off the pixel grid by a fraction of a pixel) and the start's
    offset along each axis."""
    rows, cols = opt.shape
    return (rows - 1) / 2 + 0.3, (cols - 1) / 2 - 0.4, opt.start_offset_px / math.sqrt(2.0)


def _grid(opt: ModelStudyOptions) -> np.ndarray:
    rr, cc = np.mgrid[0 : opt.shape[0], 0 : opt.shape[1]]
    return np.stack([rr.ravel(), cc.ravel()], -1).astype(float)


def _band(opt: ModelStudyOptions, ref: LimbParams, model: LimbModel) -> np.ndarray:
    """The pixels within ``opt.annulus`` px of the limb of the sigmoid ``ref`` (circle or ellipse), in the model's
    own distance: for ``k = 1`` the sigmoid is ``1/(1 + exp(d - R))``, so ``d - R = log(1/f - 1)``."""
    grid = _grid(opt)
    f_ref = np.asarray(model.intensity(ref.replace(k=1.0, ymax=1.0, ymin=0.0), jnp.asarray(grid)))
    with np.errstate(divide="ignore"):
        dist = np.log(np.clip(1.0 / np.clip(f_ref, 1e-300, 1.0) - 1.0, 1e-300, None))
    return grid[np.abs(dist) <= opt.annulus]


def _sigmoid_problem(opt: ModelStudyOptions) -> tuple[LimbParams, LimbParams, np.ndarray]:
    r0, c0, d = _centre(opt)
    if opt.model == "circle":
        truth: LimbParams = CircleParams(r0, c0, opt.radius, opt.k, opt.ymax, opt.ymin)
        init: LimbParams = CircleParams(r0 + d, c0 - d, opt.radius + opt.start_offset_px, opt.k, opt.ymax, opt.ymin)
        return truth, init, _band(opt, init, CIRCLE)
    truth = EllipseParams(r0, c0, opt.radius, opt.theta, opt.rho, opt.k, opt.ymax, opt.ymin)
    init = EllipseParams(r0 + d, c0 - d, opt.radius + opt.start_offset_px, opt.theta + 0.01, opt.rho, opt.k, opt.ymax,
                         opt.ymin)
    return truth, init, _band(opt, init, ELLIPSE)


def _linear_problem(opt: ModelStudyOptions) -> tuple[LimbParams, LimbParams, np.ndarray]:
    """A straight vertical edge at column ``(cols - 1)/2 - 0.4`` of a ``rows``-tall frame: every pixel of the
    band contributes its column (the 1-D model's coordinate)."""
    _, xt, _ = _centre(opt)
    init = LinearParams(xt + opt.start_offset_px, opt.k, opt.ymax, opt.ymin)
    cols = np.arange(math.ceil(xt + opt.start_offset_px - opt.annulus), math.floor(xt + opt.start_offset_px + opt.annulus) + 1)
    return LinearParams(xt, opt.k, opt.ymax, opt.ymin), init, np.tile(cols.astype(float), opt.shape[0])


def _ramp_problem(opt: ModelStudyOptions) -> tuple[LimbParams, LimbParams, np.ndarray]:
    """The ramp: a limb brightening toward the edge (``g2 < 0``, ``g > 0``) and a level varying along the arc."""
    r0, c0, d = _centre(opt)
    shape = dict(theta=opt.theta, rho=opt.rho, k=opt.k, ymax=opt.ymax, ymin=opt.ymin)
    truth = EllipseRampParams(r0, c0, opt.radius, **shape, g=0.4, g2=-3.0, h1=6.0, h2=-4.0, h3=0.0, h4=0.0)
    init = truth.replace(r0=r0 + d, c0=c0 - d, a=opt.radius + opt.start_offset_px, g=0.0, g2=0.0, h1=0.0, h2=0.0)
    ref = EllipseParams(r0 + d, c0 - d, opt.radius + opt.start_offset_px, opt.theta, opt.rho, opt.k, opt.ymax, opt.ymin)
    return truth, init, _band(opt, ref, ELLIPSE)


def _profile_problem(opt: ModelStudyOptions) -> tuple[LimbParams, LimbParams, np.ndarray]:
    """The lunar-Lambert profile of a Moon at 150 000 km and 45 deg phase lit from ``+col``: the band's lit half
    (within 80 deg of the Sun's image direction)."""
    r0, c0, d = _centre(opt)
    phase = math.radians(_PHASE_DEG)
    inv_f = math.tan(math.asin(_MOON_RADIUS_KM / _MOON_RANGE_KM)) / opt.radius
    truth = LimbProfileParams(r0, c0, opt.radius, 0.0, 1.0, _PSF_PX, opt.ymax - opt.ymin, opt.ymin, 0.0, 1.0, phase,
                              inv_f, lunar_lambert_weight(phase), lunar_lambert_slope(phase), lunar_lambert_weight(phase))
    init = truth.replace(r0=r0 + d, c0=c0 - d, a=opt.radius + opt.start_offset_px)
    coords = _band(opt, CircleParams(r0 + d, c0 - d, opt.radius + opt.start_offset_px, 1.0, 1.0, 0.0), CIRCLE)
    ang = np.arctan2(coords[:, 0] - (r0 + d), coords[:, 1] - (c0 - d))
    return truth, init, coords[np.abs(ang) <= math.radians(80.0)]


def _disc_problem(opt: ModelStudyOptions) -> tuple[LimbParams, LimbParams, np.ndarray]:
    """The limb-darkened disc of a star (the Sun's coefficients 0.6, 0.1) with a 0.8 px PSF, all round."""
    r0, c0, d = _centre(opt)
    truth = LimbDarkenedParams(r0, c0, opt.radius, _PSF_PX, opt.ymax - opt.ymin, opt.ymin, 0.6, 0.1)
    init = truth.replace(r0=r0 + d, c0=c0 - d, a=opt.radius + opt.start_offset_px)
    return truth, init, _band(opt, CircleParams(r0 + d, c0 - d, opt.radius + opt.start_offset_px, 1.0, 1.0, 0.0), CIRCLE)


_BUILDERS = {"linear": _linear_problem, "circle": _sigmoid_problem, "ellipse": _sigmoid_problem,
             "ellipse_ramp": _ramp_problem, "lunar_limb": _profile_problem, "limb_darkened": _disc_problem}


def standard_problem(opt: ModelStudyOptions) -> StudyProblem:
    """The study problem of ``opt`` (module docstring).

    Parameters
    ----------
    opt : ModelStudyOptions
        Model, image shape, limb geometry, noise, band half-width, start offset and fixed parameters.

    Returns
    -------
    StudyProblem
        The truth, the start, the band pixels ``(n, 2)`` as (row, col) (``(n,)`` columns for ``linear``), the
        fixed parameters (``opt.fixed`` with :data:`ALWAYS_FIXED`) and ``sigma`` (DN).
    """
    truth, init, coords = _BUILDERS[opt.model](opt)
    fixed = tuple(sorted(set(opt.fixed) | set(ALWAYS_FIXED.get(opt.model, ()))))
    return StudyProblem(_MODELS[opt.model], truth, init, coords, fixed, float(opt.sigma),
                        label=f"{opt.model} {opt.radius:g} px, sigma {opt.sigma:g} DN")


def model_problem(opt: ModelStudyOptions) -> tuple[LimbModel, LimbParams, LimbParams, np.ndarray, tuple[str, ...]]:
    """:func:`standard_problem` as ``(model, truth, init, coords, fixed)``.

    Parameters
    ----------
    opt : ModelStudyOptions
        The study.

    Returns
    -------
    model : LimbModel
    truth, init : LimbParams
        True parameters and the start of every fit.
    coords : np.ndarray (n, 2)
        Band pixels as (row, col) (``(n,)`` columns for ``linear``).
    fixed : tuple of str
        Parameters held at the truth.
    """
    p = standard_problem(opt)
    return p.model, p.truth, p.init, p.coords, p.fixed


__all__ = ["ALWAYS_FIXED", "STUDY_MODELS", "ModelStudyOptions", "StudyProblem", "estimated_nbytes", "model_problem",
           "standard_problem"]
