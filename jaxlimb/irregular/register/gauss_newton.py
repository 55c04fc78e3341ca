r"""Photometric Gauss-Newton (Lucas-Kanade with re-rendering), coarse to fine.

Each iteration renders the model ``M`` (radiance, unit albedo) at the current centre image ``P`` and
range ``D`` (scale ``s = -ln D``; body centre at ``t = D u(P)``, Eq. 4 of Wu et al.), solves the linear
problem of :mod:`.design` on the window around the body and moves the pose.  The blurred iterations
run on the pyramid (:mod:`.pyramid`); with the attitude fitted, the unblurred ones first on the
2x2-averaged frame, the last ones at full resolution.  Before the first sharp full-resolution
iteration the camera's PSF is estimated (:func:`estimate_psf`, a blur of the model only); a sharp
step that reverses the last one is halved (the rendering's sub-pixel quantisation otherwise makes
a limit cycle).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...errors import ConvergenceError
from ..mesh import Mesh
from ..model_render import mix_laws
from .design import Columns, Solve, solve, surge_fields, system
from .options import RegisterOptions
from .pyramid import COARSE_MIN_LEVEL, LevelModel, Pyramid, blur_schedule, figure_size, half_resolution_allowed, level_of, render_level

TOL_PX = 0.01  # centre step (px) at which the sharp iterations stop
# largest last step (px) accepted as converged when max_iterations are used up: the rendering is quantised on
# the sub-pixel grid and its steps jitter at ~0.005 px
_MAX_FINAL_STEP_PX = 0.05
_PSF_GRID_PX = (0.0, 0.5, 0.9, 1.4, 2.2)  # Gaussian PSF sigmas among which estimate_psf picks the camera's
_SURGE_MIN_RANGE = 0.04  # a surge field that varies by less across the window is left out (design.surge_fields)
_MIX_BOUNDS = (-1.0, 1.0)  # the photometric mix is kept in these bounds
_MIX_LAWS_MAX_PHASE_DEG = 75.0  # from this phase on at most two laws (the third is for the zero-phase degeneracy)
PEDESTAL_MIN_DARK_FRAC = 0.02  # the pedestal column when this fraction of the covered pixels is unlit


@dataclass(frozen=True)
class Problem:
    """What is registered: the frame's pyramid, the shape model, the Sun direction (camera frame; ``None``:
    zero phase) and the options; ``fit_attitude``: three rotation columns too; ``wide``: the blur schedule of
    the attitude fit (fractions of the figure size)."""

    pyramid: Pyramid
    mesh: Mesh
    sun: np.ndarray | None
    options: RegisterOptions
    fit_attitude: bool = False
    wide: bool = False

    @property
    def camera(self) -> object:
        return self.pyramid[1].camera

    def columns(self, with_mix: bool, fields: tuple[np.ndarray, ...] = ()) -> Columns:
        """The columns of a solve of this problem (:class:`.design.Columns`).

        Parameters
        ----------
        with_mix : bool
            Include the photometric-mix columns.
        fields : tuple of np.ndarray
            Surge fields (:func:`.design.surge_fields`).

        Returns
        -------
        Columns
            Attitude, mix, albedo, surge and pedestal columns as the options ask.
        """
        o = self.options
        return Columns(self.fit_attitude, with_mix, (o.albedo_order, o.albedo_harmonics), fields, pedestal_frac(o))


@dataclass
class GNState:
    """State of the Gauss-Newton registration between stages.

    ``rms_frac`` is the RMS residual of the last solve over the fitted contrast ``a`` (comparable between
    hypotheses registered on the same frame at the same blur); ``history`` holds it for every iteration.
    """

    P: np.ndarray
    D: float
    R: np.ndarray
    ratio: float = 0.0
    mix: np.ndarray | None = None  # photometric mix (RegisterOptions.fit_photometry), None: not fitted
    psf: float = 0.0  # Gaussian PSF sigma of the model (px, estimate_psf)
    prev_step: np.ndarray | None = None  # the last sharp centre step (damping of limit cycles)
    it: int = 0
    step_px: float = math.inf
    rms_frac: float = math.nan
    last: Solve | None = None  # the last solve
    history: list = dataclasses.field(default_factory=list)


def pedestal_frac(options: RegisterOptions) -> float:
    """The dark fraction of :func:`.design.has_dark_side` for the pedestal column (0: never).

    Parameters
    ----------
    options : RegisterOptions
        ``fit_pedestal``.

    Returns
    -------
    float
        ``PEDESTAL_MIN_DARK_FRAC``, or 0 without the pedestal column.
    """
    return PEDESTAL_MIN_DARK_FRAC if options.fit_pedestal else 0.0


def initial_mix(options: RegisterOptions, phase_deg: float = 0.0) -> np.ndarray | None:
    """The initial photometric mix: ``options.mix_laws`` laws, at most two from 75 deg phase on.

    Parameters
    ----------
    options : RegisterOptions
        ``fit_photometry`` and ``mix_laws``.
    phase_deg : float
        Phase angle (deg) at the body.

    Returns
    -------
    np.ndarray or None
        Zeros (the base reflectance alone), one per mixed law plus the smooth-shading term; ``None``: not fitted.
    """
    if not options.fit_photometry:
        return None
    n = options.mix_laws if phase_deg < _MIX_LAWS_MAX_PHASE_DEG else min(options.mix_laws, 2)
    return np.zeros(len(mix_laws(n)) + 1)


def render_state(problem: Problem, st: GNState, k: int, jacobian: bool | None = None) -> LevelModel:
    """The model at pyramid factor ``k`` for the pose of ``st`` (attitude derivatives when the attitude is fitted).

    Parameters
    ----------
    problem : Problem
        The registration problem.
    st : GNState
        Current pose ``(R, P, D)`` and photometric mix.
    k : int
        Pyramid factor.
    jacobian : bool, optional
        Render the attitude derivatives; default ``problem.fit_attitude``.

    Returns
    -------
    LevelModel
        The rendered model, its window and centre in level pixels.
    """
    jac = problem.fit_attitude if jacobian is None else jacobian
    return render_level(problem.pyramid, problem.mesh, problem.sun, problem.options, k, (st.R, st.P, st.D), jac, st.mix)


def gn_step(problem: Problem, st: GNState, sigma: float, k: int, rendered: LevelModel | None = None) -> Solve:
    """One linearised solve at blur ``sigma`` and pyramid factor ``k``.

    Parameters
    ----------
    problem : Problem
        The registration problem.
    st : GNState
        Current pose, PSF, ``ratio`` and mix.
    sigma : float
        Blur of the iteration (full-resolution px).
    k : int
        Pyramid factor.
    rendered : LevelModel, optional
        The model of this pose, if already rendered.

    Returns
    -------
    Solve
        Coefficients, residual sum of squares, normal matrix and design of the solve.
    """
    lm = render_state(problem, st, k) if rendered is None else rendered
    level, o = problem.pyramid[k], problem.options
    fields = surge_fields(level.camera, lm.lo, lm.hi, lm.Pk, problem.sun, o.surge_widths, _SURGE_MIN_RANGE) if o.surge_widths else []
    cols = problem.columns(st.mix is not None, tuple(fields))
    At, y = system(lm, level.image, sigma / k, st.psf / k, st.ratio, cols)
    beta, rss, N = solve(At, y)
    return Solve(beta, rss, N, At, y, lm.lo, lm.hi, cols.n_pose)


def estimate_psf(problem: Problem, st: GNState, rendered: LevelModel | None = None) -> float:
    """Gaussian sigma (px) of the camera's PSF: the one of the grid whose blurred model leaves the smallest residual
    at the current pose (one render), refined by a parabola through the three values around the minimum.

    Parameters
    ----------
    problem : Problem
        The registration problem.
    st : GNState
        Current pose.
    rendered : LevelModel, optional
        The full-resolution model of the current pose, if made (the next iteration's: one render for both).

    Returns
    -------
    float
        PSF sigma, full-resolution px (within the grid ``_PSF_GRID_PX``).
    """
    lm = render_state(problem, st, 1, jacobian=False) if rendered is None else rendered
    grid = np.asarray(_PSF_GRID_PX, dtype=float)
    cols = Columns(pedestal=pedestal_frac(problem.options))
    cost = []
    for g in grid:
        # the pose and photometry columns only: the residual's minimum over the blur is the same, at a third of the cost
        At, y = system(lm, problem.pyramid[1].image, 0.0, float(g), st.ratio, cols)
        cost.append(solve(At, y)[1])
    i = int(np.argmin(cost))
    if 0 < i < grid.size - 1:
        c0, c1, c2 = cost[i - 1], cost[i], cost[i + 1]
        den = c0 - 2.0 * c1 + c2
        if den > 0:
            h = 0.5 * (c0 - c2) / den
            return float(grid[i] + h * (grid[i + 1] - grid[i - 1]) / 2.0)
    return float(grid[i])


def rotvec_matrix(w: np.ndarray) -> np.ndarray:
    """Rodrigues rotation of a rotation vector ``w`` (rad).

    Parameters
    ----------
    w : np.ndarray (3,)
        Rotation vector: axis times angle (rad).

    Returns
    -------
    np.ndarray (3, 3)
        Rotation matrix (identity for ``|w| < 1e-15``).
    """
    th = float(np.linalg.norm(w))
    if th < 1e-15:
        return np.eye(3)
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]) / th
    return np.eye(3) + math.sin(th) * K + (1.0 - math.cos(th)) * K @ K


def iterate(problem: Problem, st: GNState, sigma: float, k: int | None = None, rendered: LevelModel | None = None) -> bool:
    """One Gauss-Newton iteration at blur ``sigma``, updating ``st`` in place.

    The step is limited to ``2 + 2 sigma`` px, 5 % in range and 3 deg in attitude; a sharp step that reverses
    the last one is halved.

    Parameters
    ----------
    problem : Problem
        The registration problem.
    st : GNState
        State, moved in place.
    sigma : float
        Blur of the iteration (full-resolution px); 0: sharp.
    k : int, optional
        Pyramid factor; default from the blur and the figure size (:func:`.pyramid.level_of`).
    rendered : LevelModel, optional
        The model of this pose, if made (:func:`gn_step`).

    Returns
    -------
    bool
        Converged: a sharp iteration with steps below ``TOL_PX``.

    Raises
    ------
    ConvergenceError
        The fitted contrast is not positive.
    """
    if k is None:
        k = level_of(sigma, figure_size(problem.pyramid[1].mask))
    sol = gn_step(problem, st, sigma, k, rendered)
    a = float(sol.beta[0])
    if not a > 0:
        raise ConvergenceError("registration: the fitted contrast of the model is not positive")
    if st.mix is not None:
        st.mix = np.clip(st.mix + sol.beta[-len(st.mix) :] / a, *_MIX_BOUNDS)
    st.it, st.ratio, st.last = st.it + 1, float(sol.beta[1]) / a, sol
    st.rms_frac = math.sqrt(sol.rss / sol.y.size) / a
    st.history.append(st.rms_frac)
    return _move(st, sol.beta, sigma, k, problem.fit_attitude)


def _move(st: GNState, beta: np.ndarray, sigma: float, k: int, fit_attitude: bool) -> bool:
    """Apply the step of the solve ``beta`` (limited, damped); whether converged."""
    a = float(beta[0])
    step, ds = beta[2:4] / a * k, float(beta[4] / a)
    n = float(np.linalg.norm(step))
    if n > 2.0 + 2.0 * sigma:
        f = (2.0 + 2.0 * sigma) / n
        step, ds, beta = step * f, ds * f, np.concatenate([beta[:5], beta[5:] * f])
    if sigma == 0 and st.prev_step is not None and float(step @ st.prev_step) < -0.5 * n * float(np.linalg.norm(st.prev_step)):
        # a sharp step reversing the last one: the rendering's sub-pixel quantisation makes a limit
        # cycle of growing amplitude; half steps damp it to the mid-point
        step, n = 0.5 * step, 0.5 * n
    st.prev_step = step if sigma == 0 else None
    st.P = st.P + step
    st.D = st.D * math.exp(-max(min(ds, 0.05), -0.05))
    dw = 0.0
    if fit_attitude:
        w = beta[5:8] / a
        dw = float(np.linalg.norm(w))
        if dw > math.radians(3.0):
            w = w * (math.radians(3.0) / dw)
        st.R = rotvec_matrix(w) @ st.R
    prev, st.step_px = st.step_px, n
    # the attitude of an elongated body far away jitters at ~1e-3 rad, moving the centre by ~0.01 px
    return sigma == 0 and abs(ds) < 1e-4 and ((n < TOL_PX and dw < 1e-4) or max(n, prev) < 2.0 * TOL_PX)


def coarse_schedule(problem: Problem) -> tuple[float, ...]:
    """Blurs (px) of the coarse stage: the first of the blur schedule and those after it at pyramid factors of at
    least :data:`.pyramid.COARSE_MIN_LEVEL` (cheap: a 600 px figure is 75-120 px across there).

    Parameters
    ----------
    problem : Problem
        The registration problem (its lit figure and blur schedule).

    Returns
    -------
    tuple of float
        Gaussian blur (px, full resolution) of each coarse iteration, widest first.
    """
    mask = problem.pyramid[1].mask
    size = figure_size(mask)
    out: list[float] = []
    for sigma in blur_schedule(mask, problem.wide):
        if out and level_of(sigma, size) < COARSE_MIN_LEVEL:
            break
        out.append(sigma)
    return tuple(out)


def coarse_stage(problem: Problem, st: GNState, max_iterations: int | None = None) -> GNState:
    """The iterations of :func:`coarse_schedule` from ``st``'s next one on.

    Parameters
    ----------
    problem : Problem
        The registration problem.
    st : GNState
        State (a new one, or one stopped by ``max_iterations``), moved in place.
    max_iterations : int, optional
        Stop when ``st`` has made this many iterations (a later call resumes the stage); default: all of them.

    Returns
    -------
    GNState
        ``st``.
    """
    for sigma in coarse_schedule(problem)[st.it : max_iterations]:
        iterate(problem, st, sigma)
    return st


Guard = Callable[[GNState, float], None]


def fine_stage(problem: Problem, st: GNState, guard: Guard | None = None) -> GNState:
    """The rest of the blur schedule, then sharp iterations to convergence (``max_iterations`` in all).

    Parameters
    ----------
    problem : Problem
        The registration problem.
    st : GNState
        State after :func:`coarse_stage`, moved in place.
    guard : Guard, optional
        ``guard(state, sigma)``, called after every iteration; it may raise a
        :class:`~jaxlimb.errors.CheckFailed` to abandon the registration.

    Returns
    -------
    GNState
        ``st``, converged.

    Raises
    ------
    ConvergenceError
        The last step still exceeds ``_MAX_FINAL_STEP_PX`` after ``max_iterations``.
    """
    o, mask = problem.options, problem.pyramid[1].mask
    blur = blur_schedule(mask, problem.wide)
    size = figure_size(mask)
    k2 = 2 if half_resolution_allowed(size) and o.sharp_level2_iterations > 0 else 1
    n2, psf_done = 0, False
    while st.it < o.max_iterations:
        sigma = blur[st.it] if st.it < len(blur) else 0.0
        k = level_of(sigma, size)
        if n2 < o.sharp_level2_iterations:  # no full-resolution iteration before the half-resolution optimum
            k = max(k, k2)
            n2 += sigma == 0
        rendered = None
        if sigma == 0 and k == 1 and o.fit_psf and not psf_done:
            rendered = render_state(problem, st, 1)  # one render for the PSF estimate and this iteration (the same pose)
            st.psf, psf_done = estimate_psf(problem, st, rendered), True
        done = iterate(problem, st, sigma, k, rendered)
        if guard is not None:
            guard(st, sigma)
        if k > 1 and sigma == 0 and st.step_px < 4.0 * TOL_PX:
            n2 = o.sharp_level2_iterations  # converged on the half-resolution frame (its own jitter): full resolution
        elif done:
            break
    if st.step_px > _MAX_FINAL_STEP_PX:
        raise ConvergenceError(f"registration did not converge in {o.max_iterations} iterations (last step {st.step_px:.3g} px)")
    return st


__all__ = [
    "PEDESTAL_MIN_DARK_FRAC", "TOL_PX", "GNState", "Guard", "Problem", "coarse_schedule", "coarse_stage", "estimate_psf",
    "fine_stage", "gn_step", "initial_mix", "iterate", "pedestal_frac", "render_state", "rotvec_matrix",
]  # fmt: skip
