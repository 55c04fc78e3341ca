r"""``jaxlimb track --frames FRAMES.jsonl --camera C.json``: from a sequence of frames to a trajectory.

FRAMES.jsonl: one JSON object per frame and line, ``{"image": PATH, "epoch": ISO-UTC | TDB-JD, "attitude": Q|DCM,
"body": "earth"|"moon"}`` (``attitude`` as ``jaxlimb navigate --attitude``; optional ``"hints"``: the hints object
of ``locate``; optional ``"true_state"``: ``[x, y, z, vx, vy, vz]`` km, km/s, geocentric ICRF, for simulations:
errors and NEES are then reported and plotted).  Relative image paths are taken from the FRAMES file's folder.

Stage 1, the measurements: every frame is measured by :func:`jaxlimb.pipeline.locate` (the Sun's direction from
DE421 and the attitude; for the Earth its orientation from skyfield's ITRS, as ``navigate`` does; no tolerance on
the centre's sigma unless ``--max-center-sigma-px`` sets one: the filter weighs each frame by its covariance and
gates it by its NIS), one JSON line
per frame appended to ``--measurements FILE.jsonl`` as ``locate --out`` does (:mod:`jaxlimb.cli._batch`):
``--resume`` skips the frames the file holds, so an interrupted run continues, and a file made by an earlier
run (or by ``jaxlimb locate IMAGES --out``) is used as it is.  Stage 2, the trajectory
(:func:`jaxlimb.track.track`): initial orbit, iterated EKF with NIS gating, RTS smoother, batch least squares of
the arc (``--self-calibrate``: with the focal length, principal point and k1, and what the sequence cannot
observe named), each with an image bias per body (:mod:`jaxlimb.track.bias`) and the split of ``locate``'s model
error into independent, constant and walking parts estimated from the arc (:mod:`jaxlimb.track.variance`;
``--no-bias``: neither).  ``--out TRACK.jsonl`` receives one line per frame epoch (:func:`jaxlimb.track.epoch_records`),
written atomically; ``--plot`` the position error (with ``true_state``) or the filter-minus-smoother departure,
with 3-sigma envelopes.

Exit 0 on success, 2 for unusable input, 3 when too few frames were measured or the fit failed.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from .._validate import Range, arg_number
from ._inputs import add_center_tolerance, locate_options_given

_PROB = Range(0.5, 1.0, hi_open=True)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "track", help="trajectory (filter, smoother, batch fit) from a sequence of Earth/Moon frames",
        description="Measure every frame with locate (resumable), then estimate the spacecraft's trajectory: "
        "iterated EKF with NIS gating, RTS smoother, batch least squares of the arc (optionally with the camera). "
        "Exit 0 on success, 2 for unusable input, 3 when too few frames were measured or the fit failed.")
    p.add_argument("--frames", required=True, metavar="FRAMES.jsonl", help="one frame per line (module docstring)")
    p.add_argument("--camera", required=True, metavar="CAMERA.json", help="camera file (docs/formats.md)")
    p.add_argument("--measurements", metavar="FILE.jsonl", default=None,
                   help="per-frame locate records (appended; default: OUT with .locate.jsonl, else a temporary file)")
    p.add_argument("--resume", action="store_true", help="reuse the frames --measurements already holds")
    p.add_argument("--out", metavar="TRACK.jsonl", default=None, help="one trajectory line per frame epoch")
    p.add_argument("--plot", metavar="PNG", default=None, help="position error / envelope picture")
    p.add_argument("--prior", metavar="PRIOR.json", default=None,
                   help='{"epoch", "state": [6], "sigma": [6] | "covariance": 6x6}; default: initial orbit from the frames')
    p.add_argument("--self-calibrate", action="store_true", dest="calibrate",
                   help="estimate focal length, principal point and k1 with the trajectory (batch fit)")
    p.add_argument("--no-batch", action="store_true", help="filter and smoother only")
    p.add_argument("--no-bias", action="store_true",
                   help="no bias states: every frame's error independent (default: an image bias per body, constant "
                   "and walking, with how much of locate's model error each part takes estimated from the arc)")
    p.add_argument("--attitude-sigma-urad", type=arg_number(Range(0.0, 1e5)), default=10.0,
                   help="per-axis attitude knowledge, microradians (default 10)")
    p.add_argument("--process-noise", type=arg_number(Range(0.0, 1e-3)), default=1e-15,
                   help="white-acceleration PSD, km^2/s^3 (default 1e-15)")
    p.add_argument("--gate-probability", type=arg_number(_PROB), default=0.999,
                   help=f"NIS gate: chi-square quantile, {_PROB} (default 0.999: 16.27 for 3 dof)")
    p.add_argument("--ephemeris", metavar="BSP", default=None, help="JPL kernel (default: DE421 from skyfield-data)")
    add_center_tolerance(p, "none")  # the filter weighs each frame by its covariance and gates it by its NIS
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run)


def read_frames(path: str) -> list[dict[str, Any]]:
    """The FRAMES file's objects, validated (module docstring); images resolved against its folder."""
    from .._validate import input_file
    from ..errors import ConfigError

    input_file(path, "--frames")
    base = Path(path).resolve().parent
    out = []
    for i, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as e:
            raise ConfigError(f"--frames line {i}: not JSON ({e.msg})") from None
        if not isinstance(rec, dict) or not all(k in rec for k in ("image", "epoch", "attitude", "body")):
            raise ConfigError(f"--frames line {i}: needs keys image, epoch, attitude, body")
        if rec["body"] not in ("earth", "moon"):
            raise ConfigError(f"--frames line {i}: body must be earth or moon, got {rec['body']!r}")
        img = Path(str(rec["image"]))
        out.append({**rec, "image": str(img if img.is_absolute() else base / img)})
    if len(out) < 2:
        raise ConfigError(f"--frames holds {len(out)} frames; a track needs at least 2")
    return out


def _attitude(rec: dict[str, Any]) -> np.ndarray:
    from ._navigate import parse_attitude

    att = rec["attitude"]
    return parse_attitude(att if isinstance(att, str) else json.dumps(att))[0]


def _measure_fn(frames: dict[str, dict], camera, ephemeris: str | None, options: dict):  # noqa: ANN001, ANN202
    """``measure(path, image)`` for :func:`~jaxlimb.cli._batch.run_frames`: ``locate`` with the frame's hints."""
    from dataclasses import replace

    from ..imaging import Hints
    from ._navigate import earth_rotation_icrf_to_itrs, locate_body, sun_direction_camera

    def measure(path: str, image: np.ndarray) -> dict[str, Any]:
        rec = frames[path]
        C = _attitude(rec)
        hints = Hints.from_dict({**rec.get("hints", {}), "body": rec["body"]})
        if hints.sun_dir_camera is None:
            hints = replace(hints, sun_dir_camera=tuple(sun_direction_camera(rec["body"], rec["epoch"], C, ephemeris)))
        if rec["body"] == "earth" and hints.R_body_to_camera is None:
            R = C @ earth_rotation_icrf_to_itrs(rec["epoch"], ephemeris).T
            hints = replace(hints, R_body_to_camera=tuple(map(tuple, R.tolist())))
        m = locate_body(rec["body"], image, camera, hints, options)
        return {**m.to_json(), "epoch": rec["epoch"], "body": rec["body"]}

    return measure


def measurement_namespace(args: argparse.Namespace, path: Path) -> argparse.Namespace:
    """The settings that decide each frame's measurement (the frames file with its attitudes and hints, the camera,
    the ephemeris), as the batch runner's namespace: their digest is every measurement record's ``run_settings``."""
    return argparse.Namespace(command="track-measure", frames=args.frames, camera=args.camera,
                              ephemeris=args.ephemeris, **locate_options_given(args), out=str(path), resume=True,
                              workers=None, scheduler=None, quiet=getattr(args, "quiet", False))


def measure_frames(frames: list[dict], camera, args: argparse.Namespace, path: Path) -> dict[str, dict]:  # noqa: ANN001
    """Stage 1 (module docstring): the locate record of every frame, by image path."""
    from ..imaging import load_image
    from ._batch import run_frames

    ns = measurement_namespace(args, path)
    by_image = {f["image"]: f for f in frames}

    def read(p: str) -> np.ndarray:
        return load_image(p, reject_constant=False)[0]

    run_frames(list(by_image), ns, read, _measure_fn(by_image, camera, args.ephemeris, locate_options_given(args)))
    recs = {}
    for line in path.read_text().splitlines():
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(r, dict) and r.get("image") in by_image:
            recs[r["image"]] = r
    return recs


def _prior(path: str | None, eph, arc) -> tuple[float, np.ndarray, np.ndarray] | None:  # noqa: ANN001
    from .._io import read_json_file
    from .._validate import real_array
    from ..errors import ConfigError

    if path is None:
        return None
    obj = read_json_file(path, "--prior")
    if not isinstance(obj, dict) or "epoch" not in obj or "state" not in obj:
        raise ConfigError('--prior needs {"epoch", "state", "sigma" or "covariance"}')
    x = real_array(obj["state"], "--prior state")
    P = (np.diag(real_array(obj["sigma"], "--prior sigma") ** 2) if "sigma" in obj
         else real_array(obj.get("covariance"), "--prior covariance"))
    if x.shape != (6,) or P.shape != (6, 6) or np.any(np.linalg.eigvalsh(0.5 * (P + P.T)) <= 0):
        raise ConfigError("--prior: state must have 6 numbers and its covariance be 6x6 positive definite")
    return float(arc.seconds(float(eph.time(obj["epoch"]).tdb))), x, P


def _summary(res, frames, t_elapsed: float, truth) -> dict[str, Any]:  # noqa: ANN001
    from ..track import nees

    f = res.filt
    out: dict[str, Any] = {"status": "ok", "frames": len(frames), "used_by_filter": int(f.used.sum()),
                           "gated": [frames.labels[k] for k in np.nonzero(~f.used)[0]],
                           "nis_mean": float(np.mean(f.nis[f.used])), "gate_nis": f.gate, "seconds": t_elapsed}
    if res.fit is not None:
        out["batch"] = {"t_s": res.fit.t0, "state_km_kms": res.fit.x0.tolist(),
                        "sigma_km_kms": np.sqrt(np.diag(res.fit.P0)).tolist(), "residual_rms": res.fit.residual_rms,
                        "used": int(res.fit.used.sum())}
        if res.fit.bias:
            out["bias"] = res.fit.bias
        if res.fit.camera is not None:
            out["camera"] = res.fit.camera
            out["observability"] = res.fit.observability.to_json()
    if res.split is not None:
        out["model_error_split"] = res.split.to_json()
    if truth is not None:
        out["mean_nees_filtered"] = float(np.mean(nees(f.x_filt, f.P_filt, truth)))
        out["rms_position_error_smoothed_km"] = float(np.sqrt(np.mean(np.sum((f.x_smooth - truth)[:, :3] ** 2, 1))))
    return out


def run(args: argparse.Namespace) -> int:
    from ..geometry.ephemeris import clear_cache

    try:
        return _run(args)
    finally:
        clear_cache()


def _run(args: argparse.Namespace) -> int:
    import tempfile

    from .. import track as trk
    from .._io import atomic_open
    from ..errors import CheckFailed, ConfigError
    from ..geometry.camera import Camera
    from ..geometry.ephemeris import load_ephemeris
    from . import emit_json, figure_path, report_after_result, try_save

    frames_in = read_frames(args.frames)
    camera = Camera.from_json(args.camera)
    figure_path(args.plot, "--plot")
    eph = load_ephemeris(args.ephemeris)
    jd = {f["image"]: float(eph.time(f["epoch"]).tdb) for f in frames_in}  # every epoch checked before any work
    mpath = args.measurements or (str(Path(args.out).with_suffix(".locate.jsonl")) if args.out else None)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(mpath) if mpath else Path(tmp) / "locate.jsonl"
        if path.exists() and path.stat().st_size > 0 and not args.resume:
            raise ConfigError(f"--measurements {str(path)!r} exists: pass --resume to use it, or choose another file")
        recs = measure_frames(frames_in, camera, args, path)
    t_start = time.perf_counter()
    arc = trk.make_arc(min(jd.values()), max(jd.values()), ephemeris_path=args.ephemeris)
    ok = [f for f in frames_in if recs.get(f["image"], {}).get("status") == "ok"]
    if len(ok) < 8:
        raise CheckFailed(f"only {len(ok)} of {len(frames_in)} frames were measured; a track needs at least 8")
    rows = [{"image": f["image"], "t_s": float(arc.seconds(jd[f["image"]])), "C_ci": _attitude(f), "body": f["body"],
             "measurement": recs[f["image"]]} for f in ok]
    frames = trk.frames_from_records(rows, arc, camera, attitude_sigma_rad=args.attitude_sigma_urad * 1e-6)
    truth = None
    if all("true_state" in f for f in ok):
        by = {f["image"]: np.asarray(f["true_state"], float) for f in ok}
        truth = np.array([by[lab] for lab in frames.labels])
    prop = trk.Propagator(arc.table)
    res = trk.track(frames, prop, prior=_prior(args.prior, eph, arc), batch=not args.no_batch, calibrate=args.calibrate,
                    q=args.process_noise, gate_probability=args.gate_probability, bias=not args.no_bias)
    bstates = res.fit.states(prop, res.frames.t) if res.fit is not None else None
    records = trk.epoch_records(res.frames, res.filt, res.fit, arc.jd0, bstates, truth)
    if args.out:
        with atomic_open(args.out) as fh:
            for r in records:
                fh.write(json.dumps(r, allow_nan=False) + "\n")
    out = _summary(res, res.frames, time.perf_counter() - t_start, truth)
    out["failed_frames"] = len(frames_in) - len(ok)
    err = try_save(lambda: trk.plot_track(args.plot, res.frames.t - res.frames.t[0], res.filt, truth), "--plot") if args.plot else None
    if err:
        out["plot_error"] = err
    if args.json:
        emit_json(out)
    else:
        x, s = out.get("batch", {}).get("state_km_kms"), out.get("batch", {}).get("sigma_km_kms")
        print(f"{out['frames']} frames ({out['failed_frames']} not measured), {len(out['gated'])} gated, "
              f"mean NIS {out['nis_mean']:.2f}, {out['seconds']:.1f} s")
        if x is not None:
            print("batch state at the first frame: " + " ".join(f"{v:.6g}±{e:.2g}" for v, e in zip(x, s)))
        for n, v in out.get("camera", {}).items():
            print(f"camera {n}: " + ("unobservable" if v is None else f"{v['value']:.6g} ± {v['sigma']:.2g}"))
    return report_after_result(err)
