"""Checked model-based line of sight at any phase: the entry point of ``jaxlimb los locate``.

Two modes (:class:`LosMode`):

* ``KNOWN_ATTITUDE`` -- ``R_body_to_camera`` is known (hints, SPICE): the predicted
  lit image is rendered and registered to the frame (:mod:`.register`).
* ``TEMPLATE_SEARCH`` -- the attitude is unknown: phase-aware template search over
  every template and roll (:mod:`.phase`; at zero phase, or without a Sun direction,
  the whole silhouette counts as limb), then the best ``n_verify`` distinct
  hypotheses are each registered with the attitude fitted too.

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
from .database import TemplateDatabase
from .phase import PhaseSearchOptions, phase_candidates
from .register import RegisterOptions, RegisterResult, lit_figure, phase_angle_deg, register_known_attitude
from .silhouette import figure_center


class LosMode(str, Enum):
    """How the body-centre image was found."""

    KNOWN_ATTITUDE = "known-attitude"
    TEMPLATE_SEARCH = "template-search"


@dataclass(frozen=True)
class LosOptions:
    """Options of :func:`locate_los`.

    Parameters
    ----------
    n_verify
        Distinct template hypotheses registered (attitude unknown).  Each costs a few
        coarse pyramid iterations; only the best go on at full resolution.  With 3, the
        right pose was missing on Phobos and the contact binary at 60 deg and 3x
        (``benchmarks/irregular_los.py``); with 10 both are found.
    n_retry
        When none of the ``n_verify`` hypotheses explains the frame, this many further ones (the next in the
        template search's order) are registered the same way.  On a ray-traced cratered body at 60 deg phase
        the best hypothesis within 12 deg of the attitude was the 22nd (``benchmarks/irregular_independent.py``).
    min_phase_deg
        Below this phase the lit figure is treated as the silhouette.
    ambiguity_px, ambiguity_margin
        Two accepted hypotheses more than ``ambiguity_px`` apart are ambiguous unless
        the runner-up's residual excess exceeds the best one's by ``ambiguity_margin``
        (fraction of the contrast).
    search_max_excess_frac
        Largest accepted residual excess (fraction of the contrast) when the attitude is
        fitted: three free rotation angles can twist another body's model into a better
        fit than a given attitude allows, so the acceptance is stricter than
        ``register.max_excess_frac`` (a sphere frame against Thebe's model: 0.13-0.14;
        correct fits in ``benchmarks/irregular_los.py``: at most 0.035).
    search_floor_px
        Standard deviation (px, per axis) added to the covariance when the attitude is
        fitted: the attitude's residual error (a flat cost along some rotations) moves
        the centre by more than the noise.  Calibrated on ``benchmarks/irregular_los.py
        --views 2`` (36 views, all accepted; errors median 0.006, p90 0.017, max 0.045 px):
        the mean of ``error^2 / trace(cov)`` (1 expected) is 0.89 with it, about 0.03 with
        the 0.04 px of the slower pipeline before, and 6 % of the views fall beyond the
        95 % bound (in-sample calibration; the errors are heavy-tailed).
    prune_rms_frac, prune_max_rms_frac, same_center_px
        After the coarse (pyramid) iterations of every hypothesis, one whose RMS residual
        (fraction of the contrast) exceeds the best one's by ``prune_rms_frac``, or
        ``prune_max_rms_frac``, is dropped, and one whose centre lies within ``same_center_px`` of an accepted fit is
        not refined again.  On ``benchmarks/irregular_los.py`` frames the coarse residual
        of a correct pose is 0.001-0.04 and of a wrong one 0.09-0.13.
    sharp_level2_iterations
        Unblurred iterations on the 2x2-averaged frame before full resolution when the
        attitude is fitted (:class:`~.register.RegisterOptions`).
    search_surge_widths
        :attr:`~.register.RegisterOptions.surge_widths` when the attitude is fitted: none.  The surge columns
        take 0.33 -> 0.11 px off a ray-traced zero-phase Eros of known attitude, but with three rotation
        columns they made the search worse (``benchmarks/irregular_independent.py``, 24 views: median
        0.111 -> 0.090 px, but a contact binary at 30 deg then took a pose 132 deg off, 13.8 px).
    search_mix_laws
        :attr:`~.register.RegisterOptions.mix_laws` when the attitude is fitted: the two laws of before.  The
        third (Minnaert 3/4) helps a known attitude, but with three rotation columns it let the search go
        astray (``benchmarks/irregular_independent.py --views 1``, attitude unknown, 24 views: median / p90 / max
        0.138 / 0.371 / 0.502 -> 0.122 / 0.459 / 0.757 px).
    search_max_iterations
        Gauss-Newton iterations of a hypothesis (at least ``register.max_iterations``): a template
        20-40 deg off turns by at most 3 deg per iteration, and on a ray-traced Eros at 60 deg phase
        the one right hypothesis needed more than 16 (``benchmarks/irregular_independent.py``).
    search_exact_coverage
        :attr:`~.register.RegisterOptions.exact_coverage` when the attitude is fitted: off by default.  On the
        ray-traced frames of ``benchmarks/irregular_independent.py --views 1`` it hardly moves this mode's answers
        (24 views, median / p90 / max 0.138 / 0.371 / 0.445 -> 0.148 / 0.348 / 0.503 px; the same code without it
        gave 0.138 / 0.371 / 0.502 in another run); on frames rendered with exact coverage
        (``benchmarks/irregular_los.py --views 1``, 18 views) the painter's fill is 0.026 / 0.074 / 0.081 px off
        against 0.004 / 0.010 / 0.022 with it.  Cost: Phobos at 3x its long axis, 60 deg, 2.5 -> 3.3 s CPU per
        call in-process (2026-11-26), which would break the 3 s per ``los locate`` call; both errors are far
        inside this mode's 0.3 px, so the speed wins.
    register, phase
        Options of the registration and of the template search.
    """

    n_verify: int = 10
    n_retry: int = 20
    min_phase_deg: float = 5.0
    ambiguity_px: float = 1.0
    ambiguity_margin: float = 0.01
    search_max_excess_frac: float = 0.06
    search_floor_px: float = 0.008
    prune_rms_frac: float = 0.04
    prune_max_rms_frac: float = 0.1
    same_center_px: float = 0.5
    sharp_level2_iterations: int = 6
    search_surge_widths: tuple[float, ...] = ()
    search_mix_laws: int = 2
    search_max_iterations: int = 24
    search_exact_coverage: bool = False
    register: RegisterOptions = field(default_factory=RegisterOptions)
    phase: PhaseSearchOptions = field(default_factory=PhaseSearchOptions)


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


def _sun_image_direction(sun, camera, fc, options):  # type: ignore[no-untyped-def]
    from ..imaging.prior import sun_direction_image

    if sun is None or phase_angle_deg(sun, camera, fc) < options.min_phase_deg:
        return None
    s = sun_direction_image(sun, camera, fc, min_norm=1e-6)
    return None if s is None else np.asarray(s, dtype=float)


def locate_los(
    image: np.ndarray,
    db: TemplateDatabase,
    camera: object,
    sun_dir_camera: np.ndarray | None = None,
    R_body_to_camera: np.ndarray | None = None,
    range_km: float | None = None,
    options: LosOptions = LosOptions(),
) -> LosResult:
    """Body-centre image and line of sight of an irregular body, checked (module docstring).

    Raises
    ------
    NoBodyError, TooSmallError, TooBigError
        From the segmentation.
    MatchError, AmbiguousMatchError, ConvergenceError
        No hypothesis explains the frame, or two explain it with centres apart.
    """
    img = np.asarray(image, dtype=float)
    seg = lit_figure(img)
    if R_body_to_camera is not None:
        fit = register_known_attitude(img, db.mesh, camera, R_body_to_camera, sun_dir_camera, range_km, options.register, seg)
        return LosResult(LosMode.KNOWN_ATTITUDE, fit, None, 1, 1, None)
    hyps = search_hypotheses(seg, db, camera, sun_dir_camera, options)
    ropts = search_register_options(options)
    n_tried = min(len(hyps), options.n_verify)
    fits, errors = _register_hypotheses(img, db, camera, sun_dir_camera, seg, hyps[:n_tried], ropts, options)
    if not fits and len(hyps) > n_tried:  # none explains the frame: the next best templates
        fits, more = _register_hypotheses(img, db, camera, sun_dir_camera, seg, hyps[n_tried:], ropts, options)
        errors, n_tried = errors + more, len(hyps)
    return _choose(fits, errors, n_tried, options)


def search_hypotheses(seg, db: TemplateDatabase, camera: object, sun_dir_camera, options: LosOptions) -> list:  # type: ignore[no-untyped-def]
    """The template hypotheses of the attitude-unknown search, best first (``n_verify + n_retry`` of them):
    :func:`~.phase.phase_candidates` on the lit figure ``seg`` (:func:`~.register.lit_figure`) with the Sun's
    image direction; at zero phase the whole silhouette is limb."""
    s_img = _sun_image_direction(sun_dir_camera, camera, figure_center(seg[0]), options)
    popts = options.phase
    if s_img is None:  # zero phase: the whole silhouette is limb; any direction serves for the extents
        popts, s_img = replace(popts, limb_cos=-2.0), np.array([1.0, 0.0])
    n_all = options.n_verify + options.n_retry
    return phase_candidates(seg[0], db, camera, s_img, replace(popts, n_candidates=max(popts.n_candidates, n_all)))[:n_all]


def search_register_options(options: LosOptions) -> RegisterOptions:
    """The registration options of the attitude-unknown search (:class:`LosOptions`' ``search_*`` fields)."""
    return replace(
        options.register,
        max_excess_frac=min(options.register.max_excess_frac, options.search_max_excess_frac),
        sharp_level2_iterations=options.sharp_level2_iterations,
        exact_coverage=options.search_exact_coverage,
        surge_widths=options.search_surge_widths,
        mix_laws=options.search_mix_laws,
        max_iterations=max(options.register.max_iterations, options.search_max_iterations),
    )


def _register_hypotheses(img, db, camera, sun, seg, hyps, ropts, options):  # type: ignore[no-untyped-def]
    """Coarse stage for every hypothesis, then the full-resolution stage in order of the coarse residual.

    A hypothesis is not refined further when its coarse residual exceeds the best one's
    by ``prune_rms_frac`` (it could pass neither the residual check nor the ambiguity
    test), or when its centre is already within ``same_center_px`` of an accepted fit
    (the same answer: it cannot make the match ambiguous).
    """
    from .register import complete_search_registration, start_search_registration

    regs, errors = [], []
    for h in hyps:
        try:
            regs.append((start_search_registration(img, db.mesh, camera, h.R_body_to_camera, sun, (h.center_rc, h.range_km), seg, ropts), h))
        except CheckFailed as e:
            errors.append(e)
    regs.sort(key=lambda r: r[0].state.rms_frac if math.isfinite(r[0].state.rms_frac) else math.inf)
    fits: list[tuple[RegisterResult, int]] = []
    accepted: list = []
    for reg, h in regs:
        st = reg.state
        if st.rms_frac > min(regs[0][0].state.rms_frac + options.prune_rms_frac, options.prune_max_rms_frac):
            errors.append(MatchError(f"coarse residual {st.rms_frac:.3f} of the contrast, the best hypothesis {regs[0][0].state.rms_frac:.3f}"))
            continue
        if any(float(np.linalg.norm(st.P - f.center_rc)) < options.same_center_px for f, _ in fits):
            continue
        try:
            fit = complete_search_registration(reg, _runner_up_guard(accepted, options) if accepted else None)
        except CheckFailed as e:
            errors.append(e)
            continue
        fits.append((fit, h.template_index))
        accepted.append(reg.state)
    return fits, errors


def _runner_up_guard(accepted, options):  # type: ignore[no-untyped-def]
    """Abandon a further hypothesis that cannot change the answer (:func:`_register_hypotheses`).

    ``accepted``: the :class:`~.register.GNState` of the accepted fits.  After each
    iteration of the candidate:

    * at full resolution (blur below ``2 pyramid_blur_px``), its centre within
      ``same_center_px`` of an accepted fit: the same answer;
    * from its second iteration on, an RMS residual (fraction of the contrast) above that
      of every accepted fit at the same iteration (same blur; the last one for later
      sharp iterations) by ``3 ambiguity_margin``.  On sharp iterations its residual excess
      then exceeds theirs by more than the margin too (``excess^2 = rms^2 - noise^2`` with
      ``excess <= rms``): it can neither win nor make the match ambiguous.
    """
    count = [0]
    full_res = 2.0 * options.register.pyramid_blur_px

    def guard(st, sigma) -> None:  # type: ignore[no-untyped-def]
        count[0] += 1
        if sigma < full_res and any(float(np.linalg.norm(st.P - a.P)) < options.same_center_px for a in accepted):
            raise MatchError("the hypothesis converges to an accepted fit")
        i = len(st.history) - 1
        ref = min(a.history[min(i, len(a.history) - 1)] for a in accepted)
        if count[0] >= 2 and st.rms_frac > ref + 3.0 * options.ambiguity_margin:
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
    best = replace(best, covariance_rc=best.covariance_rc + options.search_floor_px**2 * np.eye(2))
    return LosResult(LosMode.TEMPLATE_SEARCH, best, j, n_tried, len(fits), runner)


__all__ = ["LosMode", "LosOptions", "LosResult", "locate_los", "phase_angle_deg"]
