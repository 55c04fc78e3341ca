"""The inputs of ``jaxlimb locate`` and ``jaxlimb navigate``: the hints with ``--body``, a frame read from its file,
the SPICE prediction of a labelled frame (``--kernels``) and its report beside the measurement, the centre's stated
tolerance (``--max-center-sigma-px``).

The image readers and SPICE are imported when a command runs (``jaxlimb --help`` imports neither)."""

from __future__ import annotations

import argparse
from dataclasses import replace

from .._validate import Range, arg_number
from ..errors import ConfigError
from ..geometry.bodies import body_from_table
from ..geometry.hints import Hints


def read_hints(path: str | None, body: str | None, base: Hints | None = None) -> Hints:
    """Hints from ``path`` (its keys over ``base``'s, e.g. SPICE's), with ``--body`` (default the Moon); a body
    without radii (hints, the IAU table) is unusable input (exit 2)."""
    hints = Hints.from_json(path) if path is not None else None
    if base is not None:
        given = {} if hints is None else {k: v for k, v in vars(hints).items() if v is not None}
        hints = replace(base, **given)
    if body is not None:
        if hints is None:
            hints = Hints(body=body)
        elif hints.body is None:
            hints = replace(hints, body=body)
        elif hints.body != body:
            raise ConfigError(f"--body {body} contradicts the hints' body {hints.body!r}")
    elif hints is None:
        hints = Hints(body="moon")
    elif hints.body is None:
        hints = replace(hints, body="moon")
    if hints.body_radii_km is None:
        body_from_table(hints.body)
    return hints


def add_center_tolerance(p: argparse.ArgumentParser, default: str | None = None) -> None:
    """``--max-center-sigma-px PX|none``: ``LocateOptions.max_center_sigma_px``, the stated tolerance on the centre
    (a frame whose centre 1-sigma exceeds it is refused, ``center_too_uncertain``); ``none``: no limit, the covariance
    says how good the centre is.  ``default`` ``None``: the flag is absent from the namespace unless given (the
    library's default applies, :func:`locate_options_given`); else ``"none"`` or a number, as typed."""
    shown = "1, the library's" if default is None else default
    p.add_argument("--max-center-sigma-px", type=center_tolerance, metavar="PX|none",
                   default=argparse.SUPPRESS if default is None else center_tolerance(default),
                   help="refuse a frame whose centre 1-sigma (px, larger axis) exceeds PX (center_too_uncertain); "
                   f"none: no limit, the covariance says how good the centre is (default {shown})")


def locate_options_given(args: argparse.Namespace) -> dict:
    """The ``LocateOptions`` fields the command line set explicitly (today ``max_center_sigma_px``)."""
    return {k: getattr(args, k) for k in ("max_center_sigma_px",) if k in vars(args)}


def center_tolerance(text: str) -> float | None:
    """``--max-center-sigma-px``'s value: a number > 0, or ``none``."""
    if text.strip().lower() == "none":
        return None
    try:
        return arg_number(Range(0.0, None, lo_open=True))(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0 or none, got {text!r}") from None


def read_frame_file(path: str):  # noqa: ANN201
    """The :class:`~jaxlimb.imaging.formats.Frame` of ``path`` (a colour image's warning on stderr)."""
    from ..imaging import ColourImageWarning
    from ..imaging.formats import read_frame
    from . import warnings_to_stderr

    with warnings_to_stderr(ColourImageWarning):
        return read_frame(path)


def spice_prediction(args, meta):  # noqa: ANN001, ANN201
    """The SPICE prediction for the frame (``None`` without ``--kernels``)."""
    if not args.kernels:
        return None
    from ..geometry.spice import spice_geometry

    return spice_geometry(args.kernels, meta.image_time, args.instrument or meta.instrument_id,
                          args.body or meta.target_name)


def spice_report(geom, meas) -> dict:  # noqa: ANN001
    """Prediction, measured - predicted and the observer position from the measurement."""
    from ..geometry.spice import observer_from_measurement, pointing_residual

    cov = meas.covariance
    cov_rc = meas.center_covariance.tolist() if "center_r" in cov and "center_c" in cov else None
    out = {"predicted": geom.to_json(), "measured_minus_predicted": pointing_residual(geom, meas.center_rc, cov_rc)}
    if meas.los_camera is not None and meas.range_km is not None:
        out["observer_from_measurement"] = observer_from_measurement(geom, meas.los_camera, meas.range_km)
    return out


__all__ = ["read_frame_file", "read_hints", "spice_prediction", "spice_report"]
