"""From a sequence of frames to a trajectory: dynamics, filter, smoother, batch fit, camera self-calibration.

Public API::

    make_arc(jd_first, jd_last) -> Arc          # reference epoch + the Moon and Sun tabulated from DE421
    Propagator(arc.table)                       # diffrax dynamics; step_with_stm: STM by jax.jacfwd
    Frames, frames_from_records, predict        # measurements (locate's centre + radius/range) and their model
    run_filter(frames, prop, x0, P0, t0) -> FilterResult     # EKF with NIS gating + RTS smoother
    bias_model(frames) -> BiasModel             # an image bias per body, its prior from locate's model error
    variance_split(frames, prop, x, t, bias)    # how much of that model error is independent, common, walking (REML)
    fit_arc(frames, prop, t0, x_guess, calibrate=...) -> ArcFit   # batch least squares (+ self-calibration)
    track(frames, prop, calibrate=...) -> TrackResult       # initial orbit, split, filter, smoother, batch in one call
    consistency: nees, average_band, posterior_crlb; report: epoch_records, plot_track
    make_transfer, drawn_frames                 # a cislunar transfer to test them on
"""

from .bias import BiasModel as BiasModel, bias_model as bias_model
from .batch import ArcFit as ArcFit, Observability as Observability, fit_arc as fit_arc, observability as observability
from .dynamics import Arc as Arc, BodyTable as BodyTable, Propagator as Propagator, acceleration as acceleration, make_arc as make_arc
from .filter import FilterResult as FilterResult, gate_threshold as gate_threshold, run_filter as run_filter
from .measurement import (
    CAMERA_PARAMS as CAMERA_PARAMS,
    Frames as Frames,
    camera_theta as camera_theta,
    frames_from_records as frames_from_records,
    predict as predict,
    single_frame_position as single_frame_position,
)
from .consistency import average_band as average_band, nees as nees, posterior_crlb as posterior_crlb
from .report import epoch_records as epoch_records, plot_track as plot_track
from .sequence import TrackResult as TrackResult, filter_with_split as filter_with_split, initial_guess as initial_guess, track as track
from .variance import VarianceSplit as VarianceSplit, variance_split as variance_split
from .scenario import Transfer as Transfer, drawn_frames as drawn_frames, make_transfer as make_transfer, nominal_noise as nominal_noise

__all__ = ["CAMERA_PARAMS", "Arc", "ArcFit", "BiasModel", "BodyTable", "FilterResult", "Frames", "Observability", "Propagator",
           "TrackResult", "Transfer", "VarianceSplit", "average_band", "epoch_records", "initial_guess", "nees", "plot_track", "posterior_crlb", "track", "acceleration", "bias_model", "camera_theta", "drawn_frames", "filter_with_split", "fit_arc", "frames_from_records", "gate_threshold",
           "make_arc", "make_transfer", "nominal_noise", "observability", "predict", "run_filter", "single_frame_position", "variance_split"]
