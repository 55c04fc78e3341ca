"""Render-and-register entry points: the attitude known, or fitted from a template hypothesis.

:func:`register_known_attitude` runs the whole chain (start, Gauss-Newton, checks, lit limb);
:func:`start_search_registration` and :func:`complete_search_registration` split it for the
attitude-unknown search, which ranks its hypotheses between the cheap coarse stage and the
full-resolution one (:mod:`jaxlimb.irregular.locate`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ...errors import ConvergenceError
from ..limb_edges import combine, lit_limb_center
from ..mesh import Mesh
from .checks import finish_registration
from .gauss_newton import GNState, Guard, Problem, coarse_stage, fine_stage, initial_mix
from .options import RegisterOptions, RegisterResult
from .pyramid import Pyramid, frame_pyramid, pose
from .start import coarse_ncc, lit_figure, start_pose, sun_phase_deg

# the lit limb's points: model radiance inside at least this fraction of the body's, profiles of +-_LIMB_HALF_PX
_LIMB_LIT_FRAC = 0.3
_LIMB_HALF_PX = 5.0
_LIMB_FLOOR_PX = 0.03  # standard deviation (px, per axis) added to the edge estimate's covariance
# the edge estimate is not used when the robust scatter of its shifts exceeds this (the model's outline does not
# follow the body's: a shape model coarser than the body)
_LIMB_MAX_SCATTER_PX = 0.35


def _gauss_newton(problem: Problem, R: np.ndarray, P: np.ndarray, D: float) -> GNState:
    """Coarse to fine from the pose ``(R, P, D)``: the blurred iterations first, on the pyramid."""
    mix = initial_mix(problem.options, sun_phase_deg(problem.camera, P, problem.sun))
    st = GNState(np.asarray(P, dtype=float), float(D), np.asarray(R, dtype=float), mix=mix)
    coarse_stage(problem, st)
    return fine_stage(problem, st)


def register_known_attitude(
    image: np.ndarray, mesh: Mesh, camera: object, R_body_to_camera: np.ndarray, sun_dir_camera: np.ndarray | None = None,
    range_km: float | None = None, options: RegisterOptions = RegisterOptions(),
    segmentation: tuple[np.ndarray, float] | None = None, fit_attitude: bool = False,
    initial: tuple[np.ndarray, float] | None = None,
) -> RegisterResult:  # fmt: skip
    """Body-centre image of a body of known attitude by render-and-register (:mod:`jaxlimb.irregular.register`).

    Parameters
    ----------
    image, camera
        Grey frame ``[row, col]`` and its :class:`~jaxlimb.geometry.camera.Camera`.
    mesh
        Shape model (km, body frame; the mesh origin is the body centre).
    R_body_to_camera
        Known attitude (``x_cam = R x_body``).
    sun_dir_camera
        Unit vector from the body toward the Sun (camera frame); ``None``: zero phase.
    range_km
        Range prior (initial value only); ``None``: from the figure's size.
    options
        Registration options.
    segmentation
        ``(mask, threshold)`` of :func:`~.start.lit_figure`, if already segmented.
    fit_attitude
        Also fit a small rotation of ``R_body_to_camera`` (three columns from the same render,
        :func:`~jaxlimb.irregular.model_render.attitude_columns`; used when the attitude comes from a
        template match, not from the hints).
    initial
        ``(P, D)`` to start from instead of the lit figure (e.g. a template match).

    Returns
    -------
    RegisterResult
        Centre ``center_rc`` (px, ``(row, col)``), its covariance, line of sight, range and the quality measures.

    Raises
    ------
    MatchError, CenterTooUncertainError, ConvergenceError
        The registered model does not explain the frame (residual, overlap), measures the centre too loosely,
        or does not converge.
    """
    img = np.asarray(image, dtype=float)
    R = np.asarray(R_body_to_camera, dtype=float)
    mask, thr = lit_figure(img) if segmentation is None else segmentation
    problem = Problem(Pyramid(img, camera, mask), mesh, sun_dir_camera, options, fit_attitude, wide=fit_attitude)
    P, D, ncc = start_pose(problem, R, range_km, initial)
    try:
        st = _gauss_newton(problem, R, P, D)
    except ConvergenceError:
        if fit_attitude:
            raise
        # a poor start (a non-convex body's extents): again with the coarse-to-fine blur of the attitude fit
        st = _gauss_newton(dataclasses.replace(problem, wide=True), R, P, D)
    res = finish_registration(problem, thr, st, ncc)
    lim = options.limb_min_phase_deg
    if fit_attitude or lim is None or sun_dir_camera is None or sun_phase_deg(camera, res.center_rc, sun_dir_camera) < lim:
        return res
    return with_lit_limb(res, st, camera)


def with_lit_limb(res: RegisterResult, st: GNState, camera: object) -> RegisterResult:
    """``res`` with its centre combined with the lit limb's estimate (:mod:`jaxlimb.irregular.limb_edges`,
    :attr:`.RegisterOptions.limb_min_phase_deg`), from the last solve of ``st`` (sharp, full resolution).

    The fitted model of that solve is linearised at the centre before its last step: the edge estimate is a
    shift of that point.  The reported covariance stays the registration's: the edge estimate's sandwich
    alone under-reports.

    Parameters
    ----------
    res : RegisterResult
        The registration.
    st : GNState
        Its converged Gauss-Newton state.
    camera : Camera
        Camera of the frame (the new line of sight).

    Returns
    -------
    RegisterResult
        ``res`` with ``center_rc``, ``los_camera`` and ``t_camera`` moved; ``res`` itself when the edge estimate
        has too few points or too wide a scatter.
    """
    sol = st.last
    if sol is None:
        return res
    lo, hi = sol.lo, sol.hi
    shape = (hi[0] - lo[0] + 1, hi[1] - lo[1] + 1)
    F = sol.fitted_radiance().reshape(shape)
    P_lin = st.P - (st.prev_step if st.prev_step is not None else 0.0)
    edge = lit_limb_center(F, sol.y.reshape(shape), 1.0 - sol.At[1].reshape(shape), P_lin - lo, _LIMB_LIT_FRAC, _LIMB_HALF_PX)
    if edge is None or not edge[2] <= _LIMB_MAX_SCATTER_PX:
        return res
    P, _ = combine(res.center_rc, res.covariance_rc, edge[0] + lo, edge[1] + _LIMB_FLOOR_PX**2 * np.eye(2))
    los = np.asarray(camera.los(P), dtype=float)  # type: ignore[attr-defined]
    return dataclasses.replace(res, center_rc=P, los_camera=los, t_camera=pose(camera, P, res.range_km))


@dataclass
class Registration:
    """A registration with the attitude fitted, stopped after the coarse stage (:func:`start_search_registration`);
    ``threshold``: the segmentation's grey level."""

    problem: Problem
    threshold: float
    state: GNState
    ncc: float


def start_search_registration(
    image: np.ndarray, mesh: Mesh, camera: object, R: np.ndarray, sun: np.ndarray | None, initial: tuple[np.ndarray, float],
    segmentation: tuple[np.ndarray, float], options: RegisterOptions = RegisterOptions(), coarse_iterations: int | None = None,
) -> Registration:  # fmt: skip
    """NCC and the coarse (pyramid) iterations of a template hypothesis, attitude fitted; cheap.

    ``state.rms_frac`` then ranks the hypotheses before the expensive full-resolution iterations
    (:func:`complete_search_registration`).

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Grey frame.
    mesh : Mesh
        Shape model (km, body frame).
    camera : Camera
        Camera of the frame.
    R : np.ndarray (3, 3)
        Body-to-camera rotation of the hypothesis.
    sun : np.ndarray (3,) or None
        Unit vector toward the Sun, camera frame; ``None``: zero phase.
    initial : (np.ndarray (2,), float)
        The hypothesis' centre image ``P`` (px) and range ``D`` (km).
    segmentation : (np.ndarray, float)
        ``(mask, threshold)`` of :func:`~.start.lit_figure`.
    options : RegisterOptions
        Registration settings.
    coarse_iterations : int, optional
        Stop after this many coarse iterations (:func:`~.gauss_newton.coarse_stage` resumes); default: all.

    Returns
    -------
    Registration
        The problem, the state after the coarse stage and the NCC peak.
    """
    img = np.asarray(image, dtype=float)
    R = np.asarray(R, dtype=float)
    problem = Problem(frame_pyramid(img, camera, segmentation[0]), mesh, sun, options, fit_attitude=True, wide=True)
    P, D, ncc = coarse_ncc(problem, R, initial)
    st = coarse_stage(problem, GNState(np.asarray(P, dtype=float), float(D), R, mix=initial_mix(options)), coarse_iterations)
    return Registration(problem, segmentation[1], st, ncc)


def complete_search_registration(reg: Registration, guard: Guard | None = None) -> RegisterResult:
    """The full-resolution iterations and the checks of a :func:`start_search_registration`.

    Parameters
    ----------
    reg : Registration
        A registration after its coarse stage.
    guard : Guard, optional
        Called after each iteration (:func:`~.gauss_newton.fine_stage`), may abandon it.

    Returns
    -------
    RegisterResult
        The checked registration.

    Raises
    ------
    MatchError, CenterTooUncertainError, ConvergenceError
        As :func:`register_known_attitude`.
    """
    st = fine_stage(reg.problem, reg.state, guard)
    return finish_registration(reg.problem, reg.threshold, st, reg.ncc)


__all__ = ["Registration", "complete_search_registration", "register_known_attitude", "start_search_registration", "with_lit_limb"]
