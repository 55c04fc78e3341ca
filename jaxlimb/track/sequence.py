"""One call from a sequence's measurements to its trajectory: initial orbit, batch fit (with the camera if asked),
filter and smoother.

Initial orbit (when no prior is given).  Each of the first frames alone gives a position
(:func:`~jaxlimb.track.measurement.single_frame_position`); a straight line through the first ``n_line`` of them
gives a first state at the first frame's time, which batch fits of the first 6, 12, ... ``n_init`` frames refine
(a longer arc from a poor guess is too far from linear for the least squares).  The filter starts from that state
with its covariance inflated ``prior_inflation`` times (sigma x 10 by default), so that the frames the start used
weigh 1 % of their weight a second time: a loose prior, not a second use of the data.

Order.  Filter and smoother run first; the batch fit of the whole arc (and the camera's self-calibration) starts
from the smoothed state at the reference time, close enough for Gauss--Newton over days of flight; with
``calibrate`` the split, the filter and the smoother are run again with the calibrated camera.

Bias states.  With ``bias`` (the default) the filter, the smoother and the batch fit estimate the bodies'
image biases with the trajectory (:mod:`jaxlimb.track.bias`).  How much of ``locate``'s model error is
independent from frame to frame, common to a body's frames, or common and slowly varying is estimated from the
arc (:mod:`jaxlimb.track.variance`): a first filter and smoother with the whole model error in both the frames'
covariances and the bias prior give the trajectory the split is linearised about; the filter, the smoother and
the batch fit then run with the split.  Frames without ``locate``'s noise/model split get no bias states and
no split.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import ConfigError
from .batch import ArcFit, fit_arc
from .bias import BiasModel, bias_model
from .dynamics import Propagator
from .filter import FilterResult, run_filter
from .measurement import Frames, single_frame_position
from .variance import VarianceSplit, variance_split


@dataclass(frozen=True)
class TrackResult:
    """Everything :func:`track` computed.

    Attributes
    ----------
    frames : the frames used (with the calibrated camera when ``calibrate``).
    filt : filter and smoother.
    fit : the batch fit of the whole arc (``None`` when not asked).
    prior : ``(t0, x0, P0)`` the filter started from.
    split : the estimated split of the bodies' model error (``None`` without bias states or a noise/model split).
    """

    frames: Frames
    filt: FilterResult
    fit: ArcFit | None
    prior: tuple[float, np.ndarray, np.ndarray]
    split: VarianceSplit | None = None


def initial_guess(frames: Frames, n_line: int = 12) -> np.ndarray:
    """State at ``frames.t[0]`` from a straight line through the first single-frame positions (module docstring)."""
    n = min(n_line, len(frames))
    if n < 2:
        raise ConfigError("an initial orbit needs at least 2 frames")
    P = np.array([single_frame_position(frames, k) for k in range(n)])
    dt = frames.t[:n] - frames.t[0]
    A = np.column_stack([np.ones(n), dt])
    coef, *_ = np.linalg.lstsq(A, P, rcond=None)
    return np.concatenate([coef[0], coef[1]])


def initial_orbit(frames: Frames, prop: Propagator, *, n_init: int = 20, inflation: float = 100.0,
                  gate_probability: float = 0.999) -> tuple[float, np.ndarray, np.ndarray]:
    """``(t0, x0, P0)`` at the first frame from the first ``n_init`` frames (module docstring)."""
    x = initial_guess(frames)
    fit = None
    for n in sorted({min(k, n_init, len(frames)) for k in (6, 12, n_init)}):
        use = np.arange(len(frames)) < n
        fit = fit_arc(frames, prop, float(frames.t[0]), x, gate_probability=gate_probability, use=use)
        x = fit.x0
    assert fit is not None
    return float(frames.t[0]), fit.x0, fit.P0 * inflation


def track(frames: Frames, prop: Propagator, *, prior: tuple[float, np.ndarray, np.ndarray] | None = None,
          batch: bool = True, calibrate: bool = False, q: float = 1e-15, gate_probability: float = 0.999,
          n_init: int = 20, prior_inflation: float = 100.0, bias: bool = True) -> TrackResult:
    """Trajectory of ``frames`` (module docstring).

    Parameters
    ----------
    prior
        ``(t0, x0, P0)``; default the initial orbit of the first ``n_init`` frames (module docstring).
    batch, calibrate
        Fit the whole arc in one least-squares problem; estimate the camera in it (then the filter runs again
        with the calibrated camera).
    q, gate_probability
        :func:`~jaxlimb.track.filter.run_filter`'s process noise and gate.
    bias
        Estimate the bodies' bias states (module docstring).
    """
    prior_given = prior
    if prior is None:
        prior = initial_orbit(frames, prop, n_init=n_init, inflation=prior_inflation, gate_probability=gate_probability)
    t0, x0, P0 = prior
    user_prior = None if prior_given is None else (prior_given[1], prior_given[2])
    kw = {"q": q, "gate_probability": gate_probability}
    measured = frames
    frames, bm, filt, split = filter_with_split(measured, prop, (t0, x0, P0), bias, **kw)
    fit = None
    if batch or calibrate:
        guess = filt.x_smooth[0] if t0 == frames.t[0] else x0
        t_ref = float(frames.t[0]) if t0 == frames.t[0] else t0
        fit = fit_arc(frames, prop, t_ref, guess, prior=user_prior, calibrate=calibrate, gate_probability=gate_probability,
                      bias=bm)
    if calibrate and fit is not None:  # the start and the split again, with the calibrated camera
        measured = replace(measured, theta=np.tile(fit.theta, (len(measured), 1)))
        if prior_given is None:
            t0, x0, P0 = initial_orbit(measured, prop, n_init=n_init, inflation=prior_inflation,
                                       gate_probability=gate_probability)
        frames, bm, filt, split = filter_with_split(measured, prop, (t0, x0, P0), bias, **kw)
    return TrackResult(frames, filt, fit, (t0, np.asarray(x0), np.asarray(P0)), split)


def filter_with_split(frames: Frames, prop: Propagator, prior: tuple[float, np.ndarray, np.ndarray], bias: bool,
                      **kw: float) -> tuple[Frames, BiasModel | bool, FilterResult, VarianceSplit | None]:
    """Filter and smoother with the bodies' model error split (module docstring): ``(frames, bias, filt, split)``,
    the frames with the split's covariances and the bias states with its prior and walk (``bias`` False: the
    plain filter, no split)."""
    t0, x0, P0 = prior
    filt = run_filter(frames, prop, x0, P0, t0, bias=bias, **kw)
    if not bias:
        return frames, False, filt, None
    bm = bias_model(frames)
    split = variance_split(frames, prop, filt.x_smooth[0], float(frames.t[0]), bm, filt.used)
    if split is None:
        return frames, bm, filt, None
    frames, bm = split.apply(frames, bm)
    return frames, bm, run_filter(frames, prop, x0, P0, t0, bias=bm, **kw), split


__all__ = ["TrackResult", "filter_with_split", "initial_guess", "initial_orbit", "track"]
