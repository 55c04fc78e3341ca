"""Checked model-based line of sight at any phase: the entry point of ``jaxlimb los locate``.

The answer is the image ``P`` of the body centre and its line of sight ``u(P)`` (Eq. 4 of Wu et al.),
with a covariance.  Two modes (:class:`LosMode`):

* ``KNOWN_ATTITUDE`` -- ``R_body_to_camera`` is known (hints, SPICE): the predicted
  lit image is rendered and registered to the frame (:mod:`.register`).
* ``TEMPLATE_SEARCH`` -- the attitude is unknown: phase-aware template search over
  every template and roll (:mod:`.phase`, the templates of Eq. 5-14; at zero phase, or
  without a Sun direction, the whole silhouette counts as limb), then the best
  ``n_verify`` distinct hypotheses are each registered with the attitude fitted too.

Checks (typed failures, CLI exit 3): every registration checks its residual against
the noise and the overlap of the figures (:class:`~jaxlimb.errors.MatchError`); when
no hypothesis passes, the frame is not explained by the shape model.  When two
hypotheses that pass put the body centre more than ``ambiguity_px`` apart with
comparable residuals, the match is ambiguous
(:class:`~jaxlimb.errors.AmbiguousMatchError`): never ``ok`` with a gross error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from ..errors import AmbiguousMatchError, CheckFailed, MatchError
from ..imaging.prior import sun_direction_image
from .database import TemplateDatabase
from .phase import PoseHypothesis, phase_candidates
from .register import (
    RegisterOptions,
    RegisterResult,
    complete_search_registration,
    lit_figure,
    phase_angle_deg,
    register_known_attitude,
    start_search_registration,
)
from .register.gauss_newton import GNState, Guard, coarse_schedule, coarse_stage
from .register.pyramid import PYRAMID_BLUR_PX
from .silhouette import figure_center

_MIN_PHASE_DEG = 5.0  # below this phase the lit figure is treated as the silhouette
# standard deviation (px, per axis) added to the covariance when the attitude is fitted: its residual error (a
# flat cost along some rotations) moves the centre by more than the noise (calibrated on
# benchmarks/irregular_los.py --views 2: mean error^2 / trace(cov) about 1)
_SEARCH_FLOOR_PX = 0.008
# after each coarse iteration a hypothesis whose RMS residual (fraction of the contrast) exceeds the best one's by
# _PRUNE_RMS_FRAC, or exceeds _PRUNE_MAX_RMS_FRAC, is dropped (a correct pose: 0.001-0.04, a wrong one: 0.09-0.13)
_PRUNE_RMS_FRAC = 0.04
_PRUNE_MAX_RMS_FRAC = 0.1
_SAME_CENTER_PX = 0.5  # a hypothesis whose centre lies this close to an accepted fit is the same answer


class LosMode(str, Enum):
    """How the body-centre image was found."""

    KNOWN_ATTITUDE = "known-attitude"
    TEMPLATE_SEARCH = "template-search"


def _search_register_options() -> RegisterOptions:
    """The registration of a template hypothesis (attitude fitted): :attr:`LosOptions.search`'s default."""
    return RegisterOptions(max_iterations=24, sharp_level2_iterations=6, max_excess_frac=0.06, surge_widths=(), mix_laws=2,
                           exact_coverage=False, coarse_cast_shadows=False)  # fmt: skip


@dataclass(frozen=True)
class LosOptions:
    """Options of :func:`locate_los`.

    Parameters
    ----------
    n_verify
        Distinct template hypotheses registered (attitude unknown).  Each costs a few coarse pyramid
        iterations; only the best go on at full resolution (with 3 the right pose was missing on Phobos and a
        contact binary at 60 deg, ``benchmarks/irregular_los.py``).
    n_retry
        When none of the ``n_verify`` hypotheses explains the frame, this many further ones (the next in the
        template search's order) are registered the same way.
    ambiguity_px, ambiguity_margin
        Two accepted hypotheses more than ``ambiguity_px`` apart are ambiguous unless the runner-up's residual
        excess exceeds the best one's by ``ambiguity_margin`` (fraction of the contrast).
    register
        The registration when the attitude is known.
    search
        The registration of each template hypothesis (attitude fitted).  Against ``register``: stricter
        acceptance (three free rotation angles can twist another body's model into a better fit than a given
        attitude allows), more iterations (a template 20-40 deg off turns by at most 3 deg per iteration),
        unblurred iterations on the half-resolution frame first, and none of the surge columns, the third
        photometric law, exact coverage or cast shadows on the coarse levels (with three rotation columns the first
        two let the search go astray; the last two cost a third and a tenth more time for an error far inside this
        mode's: the coarse levels rank the hypotheses, the finer ones cast shadows).
    """

    n_verify: int = 10
    n_retry: int = 20
    ambiguity_px: float = 1.0
    ambiguity_margin: float = 0.01
    register: RegisterOptions = field(default_factory=RegisterOptions)
    search: RegisterOptions = field(default_factory=_search_register_options)


@dataclass(frozen=True)
class Frame:
    """A frame to locate the body in: the image (float), its lit figure ``(mask, threshold)``
    (:func:`~.register.lit_figure`), the camera and the Sun direction (camera frame; ``None``: unknown)."""

    image: np.ndarray
    segmentation: tuple[np.ndarray, float]
    camera: object
    sun: np.ndarray | None


@dataclass(frozen=True)
class LosResult:
    """Result of :func:`locate_los`: the registration of the chosen hypothesis, and what was tried."""

    mode: LosMode
    fit: RegisterResult
    template_index: int | None
    n_tried: int
    n_accepted: int
    runner_up_excess: float | None

    @property
    def center_rc(self) -> np.ndarray:
        return self.fit.center_rc


def _sun_image_direction(frame: Frame, fc: np.ndarray) -> np.ndarray | None:
    """Image-plane direction toward the Sun at the figure centre ``fc``; ``None`` at (near) zero phase."""
    if frame.sun is None or phase_angle_deg(frame.sun, frame.camera, fc) < _MIN_PHASE_DEG:
        return None
    s = sun_direction_image(frame.sun, frame.camera, fc, min_norm=1e-6)
    return None if s is None else np.asarray(s, dtype=float)


def locate_los(
    image: np.ndarray, db: TemplateDatabase, camera: object, sun_dir_camera: np.ndarray | None = None,
    R_body_to_camera: np.ndarray | None = None, range_km: float | None = None, options: LosOptions = LosOptions(),
) -> LosResult:  # fmt: skip
    """Body-centre image ``P`` and line of sight ``u(P)`` (Eq. 4 of Wu et al.) of an irregular body, checked.

    Parameters
    ----------
    image : np.ndarray (rows, cols)
        Grey frame indexed ``[row, col]``.
    db : TemplateDatabase
        Templates of the shape model (:func:`~.database.build_database`); a known attitude uses only ``db.mesh``.
    camera : Camera
        Pinhole camera of the frame.
    sun_dir_camera : np.ndarray (3,), optional
        Unit vector from the body toward the Sun, camera frame; ``None``: zero phase (the silhouette is all limb).
    R_body_to_camera : np.ndarray (3, 3), optional
        Known attitude (body-fixed to camera): ``KNOWN_ATTITUDE``; ``None``: ``TEMPLATE_SEARCH`` (module docstring).
    range_km : float, optional
        Range prior (km), the start of a known-attitude registration; ``None``: from the figure's size.
    options : LosOptions
        Search and registration settings.

    Returns
    -------
    LosResult
        ``fit``: centre ``center_rc`` (px, ``(row, col)``), its 2x2 ``covariance_rc``, ``los_camera``, ``range_km``.

    Raises
    ------
    NoBodyError, TooSmallError, TooBigError, MatchError, AmbiguousMatchError, ConvergenceError
        No usable figure; no hypothesis explains the frame, or two explain it with centres apart.

    Examples
    --------
    >>> from jaxlimb.geometry.camera import Camera
    >>> from jaxlimb.irregular import DatabaseOptions, build_database
    >>> from jaxlimb.irregular.shapes import gaussian_sphere
    >>> from jaxlimb.render.mesh import look_at_rotation, render_mesh
    >>> mesh = gaussian_sphere(seed=1, radius_km=10.0, subdivisions=3)
    >>> db = build_database(mesh, DatabaseOptions(step_deg=15.0, template_size_px=128), progress=False)  # coarse
    >>> cam, R, sun = Camera(rows=200, cols=200), look_at_rotation([0.3, -0.5, 0.8]), np.array([0.5, 0.0, -0.866])
    >>> frame = render_mesh(mesh.vertices, mesh.faces, cam, R, [0, 0, mesh.max_radius * cam.focal_px / 50], sun)  # 100 px
    >>> fits = [locate_los(frame.image, db, cam, sun, R_known) for R_known in (R, None)]  # attitude known, then searched
    >>> [(f.mode.value, bool(np.linalg.norm(f.center_rc - frame.center_rc) < 0.1)) for f in fits]  # true centre: 0.1 px
    [('known-attitude', True), ('template-search', True)]
    """
    img = np.asarray(image, dtype=float)
    seg = lit_figure(img)
    if R_body_to_camera is not None:
        fit = register_known_attitude(img, db.mesh, camera, R_body_to_camera, sun_dir_camera, range_km, options.register, seg)
        return LosResult(LosMode.KNOWN_ATTITUDE, fit, None, 1, 1, None)
    frame = Frame(img, seg, camera, sun_dir_camera)
    hyps = search_hypotheses(frame, db, options)
    n_tried = min(len(hyps), options.n_verify)
    fits, errors = register_hypotheses(frame, db, hyps[:n_tried], options)
    if not fits and len(hyps) > n_tried:  # none explains the frame: the next best templates
        fits, more = register_hypotheses(frame, db, hyps[n_tried:], options)
        errors, n_tried = errors + more, len(hyps)
    return _choose(fits, errors, n_tried, options)


def search_hypotheses(frame: Frame, db: TemplateDatabase, options: LosOptions) -> list[PoseHypothesis]:
    """The template hypotheses of the attitude-unknown search, best first (``n_verify + n_retry`` of them):
    :func:`~.phase.phase_candidates` on the lit figure with the Sun's image direction; at zero phase the whole
    silhouette is limb.

    Parameters
    ----------
    frame : Frame
        The frame, its lit figure, camera and Sun direction.
    db : TemplateDatabase
        Templates searched.
    options : LosOptions
        ``n_verify`` and ``n_retry`` set how many hypotheses are returned.

    Returns
    -------
    list of PoseHypothesis
        Template index, attitude, centre image (px) and range of each hypothesis, best match first.
    """
    mask = frame.segmentation[0]
    s_img = _sun_image_direction(frame, figure_center(mask))
    whole = s_img is None
    if whole:  # zero phase: any direction serves for the extents
        s_img = np.array([1.0, 0.0])
    return phase_candidates(mask, db, frame.camera, s_img, options.n_verify + options.n_retry, whole_outline=whole)


def register_hypotheses(frame: Frame, db: TemplateDatabase, hyps: list[PoseHypothesis], options: LosOptions):  # type: ignore[no-untyped-def]
    """Coarse stage for every hypothesis (:func:`coarse_hypotheses`), then the full-resolution stage in order of
    the coarse residual.

    A hypothesis is not refined further when its centre is already within ``_SAME_CENTER_PX`` of an accepted fit
    (the same answer: it cannot make the match ambiguous), or when :func:`runner_up_guard` abandons it, from its
    coarse stage on.

    Parameters
    ----------
    frame : Frame
        The frame, its lit figure, camera and Sun direction.
    db : TemplateDatabase
        Database whose ``mesh`` is registered.
    hyps : list of PoseHypothesis
        Starting poses, from :func:`search_hypotheses`.
    options : LosOptions
        ``search`` registration settings and the ambiguity margin of :func:`runner_up_guard`.

    Returns
    -------
    fits : list of (RegisterResult, int)
        Each accepted registration with its template index, in order of the coarse residual.
    errors : list of CheckFailed
        Why each rejected hypothesis failed.
    """
    regs, errors = coarse_hypotheses(frame, db, hyps, options)
    fits: list[tuple[RegisterResult, int]] = []
    accepted: list[GNState] = []
    for reg, h in regs:
        st = reg.state
        if any(float(np.linalg.norm(st.P - f.center_rc)) < _SAME_CENTER_PX for f, _ in fits):
            continue
        guard = runner_up_guard(accepted, options) if accepted else None
        try:
            if guard is not None:
                guard(st, math.inf)  # its coarse stage, against theirs: the residual alone (blurred)
            fit = complete_search_registration(reg, guard)
        except CheckFailed as e:
            errors.append(e)
            continue
        fits.append((fit, h.template_index))
        accepted.append(reg.state)
    return fits, errors


def coarse_hypotheses(frame: Frame, db: TemplateDatabase, hyps: list[PoseHypothesis], options: LosOptions):  # type: ignore[no-untyped-def]
    """NCC and coarse stage of every hypothesis, one iteration at a time, each followed by :func:`prune_coarse`.

    Parameters
    ----------
    frame, db, hyps, options
        As :func:`register_hypotheses`.

    Returns
    -------
    regs : list of (Registration, PoseHypothesis)
        The hypotheses left after their coarse stage, best coarse residual first.
    errors : list of CheckFailed
        Why each dropped hypothesis failed.
    """
    regs, errors = [], []
    for h in hyps:
        try:
            regs.append((start_search_registration(frame.image, db.mesh, frame.camera, h.R_body_to_camera, frame.sun,
                                                   (h.center_rc, h.range_km), frame.segmentation, options.search, 1), h))  # fmt: skip
        except CheckFailed as e:
            errors.append(e)
    n_coarse = len(coarse_schedule(regs[0][0].problem)) if regs else 0  # the same figure: the same schedule
    for n in range(2, n_coarse + 1):
        going = []
        for reg, h in prune_coarse(regs, errors):
            try:
                coarse_stage(reg.problem, reg.state, n)
            except CheckFailed as e:
                errors.append(e)
                continue
            going.append((reg, h))
        regs = going
    return prune_coarse(regs, errors), errors


def prune_coarse(regs: list, errors: list) -> list:  # type: ignore[type-arg]
    """The hypotheses ``(Registration, PoseHypothesis)`` in order of their residual at the same coarse iteration,
    without those whose residual exceeds the best one's by ``_PRUNE_RMS_FRAC`` or exceeds ``_PRUNE_MAX_RMS_FRAC``
    (they could pass neither the residual check nor the ambiguity test; a :class:`~jaxlimb.errors.MatchError`
    each is appended to ``errors``).

    Parameters
    ----------
    regs : list of (Registration, PoseHypothesis)
        The hypotheses after the same number of coarse iterations.
    errors : list
        Receives a :class:`~jaxlimb.errors.MatchError` for each hypothesis pruned.

    Returns
    -------
    list of (Registration, PoseHypothesis)
        The kept hypotheses, best residual first (a non-finite residual last).
    """
    regs = sorted(regs, key=lambda r: r[0].state.rms_frac if math.isfinite(r[0].state.rms_frac) else math.inf)
    if not regs:
        return regs
    best, kept = regs[0][0].state.rms_frac, []
    for reg, h in regs:
        if reg.state.rms_frac > min(best + _PRUNE_RMS_FRAC, _PRUNE_MAX_RMS_FRAC):
            errors.append(MatchError(f"coarse residual {reg.state.rms_frac:.3f} of the contrast, the best hypothesis {best:.3f}"))
        else:
            kept.append((reg, h))
    return kept


def runner_up_guard(accepted: list[GNState], options: LosOptions) -> Guard:
    """Abandon a further hypothesis that cannot change the answer (:func:`register_hypotheses`).

    After the candidate's coarse stage and each of its later iterations:

    * at full resolution (blur below ``2 PYRAMID_BLUR_PX``), its centre within ``_SAME_CENTER_PX`` of an
      accepted fit: the same answer;
    * an RMS residual (fraction of the contrast) above that of every accepted fit at the same iteration
      (same blur and pyramid level; the last one for later sharp iterations) by ``3 ambiguity_margin``.
      On sharp iterations its residual excess then exceeds theirs by more than the margin too
      (``excess^2 = rms^2 - noise^2`` with ``excess <= rms``): it can neither win nor make the match ambiguous.

    Parameters
    ----------
    accepted : list of GNState
        The Gauss-Newton states of the accepted fits (their ``history`` of RMS residuals).
    options : LosOptions
        ``ambiguity_margin``.

    Returns
    -------
    Guard
        ``guard(state, sigma)``, called after the coarse stage (``sigma`` infinite) and each later iteration;
        raises :class:`~jaxlimb.errors.MatchError` to abandon the candidate.
    """
    full_res = 2.0 * PYRAMID_BLUR_PX

    def guard(st: GNState, sigma: float) -> None:
        if sigma < full_res and any(float(np.linalg.norm(st.P - a.P)) < _SAME_CENTER_PX for a in accepted):
            raise MatchError("the hypothesis converges to an accepted fit")
        i = len(st.history) - 1
        ref = min(a.history[min(i, len(a.history) - 1)] for a in accepted)
        if st.rms_frac > ref + 3.0 * options.ambiguity_margin:
            raise MatchError(f"residual {st.rms_frac:.3f} of the contrast against {ref:.3f} of an accepted fit")

    return guard


def _choose(fits, errors, n_tried, options) -> LosResult:  # type: ignore[no-untyped-def]
    """Best accepted hypothesis; ambiguity and no-fit checks."""
    if not fits:
        why = "; ".join(sorted({f"{e.check}: {e}" for e in errors}))[:400]
        raise MatchError(f"none of the {n_tried} template hypotheses explains the frame ({why})")
    fits.sort(key=lambda f: f[0].excess_frac)
    best, j = fits[0]
    runner = None
    for other, _ in fits[1:]:
        if np.linalg.norm(other.center_rc - best.center_rc) > options.ambiguity_px:
            runner = other.excess_frac if runner is None else runner
            if other.excess_frac < best.excess_frac + options.ambiguity_margin:
                raise AmbiguousMatchError(
                    f"two poses of the shape model explain the frame about equally well (residual excess"
                    f" {best.excess_frac:.3f} and {other.excess_frac:.3f}) with body centres"
                    f" {np.linalg.norm(other.center_rc - best.center_rc):.1f} px apart"
                )
    best = replace(best, covariance_rc=best.covariance_rc + _SEARCH_FLOOR_PX**2 * np.eye(2))
    return LosResult(LosMode.TEMPLATE_SEARCH, best, j, n_tried, len(fits), runner)


__all__ = [
    "Frame", "LosMode", "LosOptions", "LosResult", "coarse_hypotheses", "locate_los", "phase_angle_deg", "prune_coarse",
    "register_hypotheses", "runner_up_guard", "search_hypotheses",
]  # fmt: skip
