"""Every real frame of ``../shared/data`` through the ``jaxlimb`` command, against its truth where it has one.

Each frame is measured the way a user would: ``jaxlimb locate FRAME --json`` with what lies beside it (the mission's
kernels with ``--kernels``, the EPIC camera and hints, ``--body`` for the Sun and Voyager's Europa), and the
Enceladus frame once more with ``jaxlimb navigate``.  Truth, independent of jaxlimb's measurement:

* SDO (``sun/``): the FITS header's WCS (:func:`jaxlimb.imaging.sdo.sun_truth_from_header`; the 512 px HMI
  image's MANIFEST numbers).  ``resampled_hmi.fits`` with its ``CROTA2 = 179.93`` dropped: the resampling kept the
  rotation keyword but not a rotated pixel grid; the circle bounding the HMI pipeline's off-disc NaN mask (drawn
  about the pipeline's own disc centre, apart from this file's WCS) is 0.004 px from the centre without it and
  0.30 px from the one with it (``benchmarks/sun_limb.py``: ``nan_mask_circle``).
* EPIC (``epic/``): the product centre (``product_center_rc``, good to ``product_center_quality_px`` = 2 px, added
  in quadrature to the measurement's sigma) and ``range_km`` from the product's metadata; the apparent radius
  times the range, the same in every frame.  Each EPIC frame runs twice: as typed (the centre tolerance of 1 px)
  and with ``--max-center-sigma-px none`` (``..._any_sigma``: every frame answered with its covariance); the
  scatter of the apparent radius times the range is over the second.
* Jupiter (``cassini/jupiter/``): the centre of the lit limb one sees, traced independently
  (``benchmarks/_limb_trace.py``; its spread added in quadrature); the range from SPICE (the ephemerides are
  good to far better than the pointing, which is tens of px off).  As typed and with ``--max-center-sigma-px none``
  (``jupiter_any_sigma``).
* Cassini Enceladus: SPICE's range (``navigate``: the observer's distance); SPICE's centre only to its pointing
  (a few px), so the centre is not judged.
* Mimas, Voyager: no truth (answered or refused, and why).

A frame with truth is ``within 5 sigma`` when every judged quantity is (the centre by its Mahalanobis distance).

``python benchmarks/real_frames.py [--only NAME,...] [--out NAME] [--figures]`` ->
``benchmarks/results/real_frames.json`` (``--figures``: the gallery ``docs/validation/real_frames/*.png`` shown by
``docs/validation/real-frames.md``, :mod:`_real_frame_figures`).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import itertools
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, save  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


def _frames() -> list[dict]:
    """The frames, the arguments of their command and how their truth is found."""
    d = DATA.resolve()
    cas = sorted(str(p) for p in (d / "cassini" / "kernels").iterdir())
    jup = sorted(str(p) for p in (d / "cassini" / "jupiter" / "kernels").iterdir()) + cas
    out = [
        {"name": "enceladus_1", "path": d / "cassini" / "N1511803932_1.IMG", "args": ["--kernels", *cas],
         "truth": "spice_range"},
        {"name": "enceladus_2", "path": d / "cassini" / "N1511803965_3.IMG", "args": ["--kernels", *cas],
         "truth": "spice_range"},
        {"name": "mimas", "path": d / "cassini" / "N1644787857_1.LBL", "args": ["--body", "mimas"], "truth": None},
        {"name": "jupiter", "path": d / "cassini" / "jupiter" / "n1352037683.2", "args": ["--kernels", *jup],
         "truth": "limb_trace"},
        {"name": "jupiter_any_sigma", "path": d / "cassini" / "jupiter" / "n1352037683.2",
         "args": ["--kernels", *jup, "--max-center-sigma-px", "none"], "truth": "limb_trace"},
    ]
    for p in sorted((d / "voyager").glob("*.IMG")):
        out.append({"name": f"voyager_{p.stem.split('_')[0]}", "path": p, "args": ["--body", "europa"], "truth": None})
    for p in sorted((d / "sun").iterdir()):
        out.append({"name": f"sun_{p.name.split('.')[0][-14:]}_{p.suffix[1:]}", "path": p, "args": ["--body", "sun"],
                    "truth": "sun_header"})
    for m in sorted((d / "epic").glob("*.metadata.json")):
        stem = str(m)[: -len(".metadata.json")]
        for ext, tol in itertools.product(("png", "jpg"), ((), ("--max-center-sigma-px", "none"))):
            out.append({"name": f"epic_{Path(stem).name[-8:]}_{ext}{'_any_sigma' if tol else ''}",
                        "path": Path(f"{stem}.{ext}"),
                        "args": ["--camera", f"{stem}.camera.json", "--hints", f"{stem}.hints.json", *tol],
                        "truth": "epic", "meta": m})
    out.append({"name": "enceladus_1_navigate", "path": d / "cassini" / "N1511803932_1.IMG", "args": ["--kernels", *cas],
                "truth": "spice_range", "command": "navigate"})
    return out


def run_command(argv: list[str]) -> tuple[int, dict, float]:
    """``jaxlimb ARGV --json`` in this process: exit code, the JSON answer, seconds."""
    from jaxlimb.cli import main

    buf, err = io.StringIO(), io.StringIO()
    t = time.perf_counter()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        code = main([*argv, "--json"])
    sec = time.perf_counter() - t
    try:
        out = json.loads(buf.getvalue().strip().splitlines()[-1])
    except (json.JSONDecodeError, IndexError):
        out = {"status": "error", "check": "no_output", "message": (buf.getvalue() + err.getvalue())[-400:]}
    return code, out, sec


def _sigma_rc(out: dict) -> np.ndarray | None:
    c = out.get("covariance") or {}
    if "center_r" not in c:
        return None
    from jaxlimb.pipeline import covariance_block
    return covariance_block(c)


def _center_verdict(out: dict, truth_rc, truth_sigma_px: float = 0.0) -> dict:
    P = _sigma_rc(out)
    e = np.asarray(out["center_rc"], float) - np.asarray(truth_rc, float)
    res = {"truth_center_rc": [float(v) for v in truth_rc], "center_error_rc": e.tolist(),
           "center_error_px": float(np.hypot(*e))}
    if P is not None:
        Pt = P + truth_sigma_px**2 * np.eye(2)
        res["sigma_rc_px"] = np.sqrt(np.diag(P)).tolist()
        res["center_mahalanobis"] = float(math.sqrt(e @ np.linalg.solve(Pt, e)))
    return res


def _range_verdict(rng: float, sigma: float | None, truth: float) -> dict:
    e = rng - truth
    return {"truth_range_km": truth, "range_error_km": e, "range_error_frac": e / truth,
            "sigma_range_km": sigma, "range_z": None if not sigma else e / sigma}


def _truth_sun(fr: dict) -> tuple[tuple[float, float], float]:
    from jaxlimb.imaging.sdo import RESAMPLED_HMI_FITS, hmi_512_truth, sun_truth_from_header

    if fr["path"].suffix == ".fits":
        from astropy.io import fits

        with fits.open(fr["path"]) as h:
            t = sun_truth_from_header(h[0].header, ignore_rotation=fr["path"].name == RESAMPLED_HMI_FITS)
    else:
        t = hmi_512_truth()
    return t.center_rc, t.radius_px


def _jupiter_truth(out: dict, img_path: Path) -> dict:
    """The traced lit limb (:mod:`_limb_trace`) with SPICE's limb shape and Sun direction."""
    from _limb_trace import limb_truth

    from jaxlimb.imaging.formats import read_frame

    pred = out["spice"]["predicted"]
    e, s = pred["ellipse"], pred["sun_dir_camera"]
    img = read_frame(img_path).data
    return limb_truth(img, e["semi_axes_px"][1] / e["semi_axes_px"][0], e["angle_rad"], math.atan2(-s[1], s[0]))


def judge(fr: dict, out: dict, cache: dict) -> dict:
    """The verdicts of one answer against the frame's truth (module docstring)."""
    kind = fr["truth"]
    if out.get("status") != "ok" or kind is None:
        return {}
    v: dict = {}
    rng = out.get("range_km")
    cov = out.get("covariance") or {}
    s_rng = math.sqrt(cov["range_km"]["range_km"]) if "range_km" in cov else None
    if fr.get("command") == "navigate":
        s_rng = None
        P = np.asarray(out["covariance_km2"], float)
        u = np.asarray(out["position_km"], float) / np.linalg.norm(out["position_km"])
        s_rng = float(math.sqrt(u @ P @ u))
        v.update(_range_verdict(float(out["range_km"]), s_rng, float(np.linalg.norm(out["spice_observer_km"]))))
    elif kind == "spice_range":
        v.update(_range_verdict(rng, s_rng, out["spice"]["predicted"]["range_km"]))
    elif kind == "sun_header":
        c, r = _truth_sun(fr)
        v.update(_center_verdict(out, c))
        v["radius_error_px"] = out["radius_px"] - r if out.get("radius_px") is not None else None
    elif kind == "epic":
        meta = json.loads(Path(fr["meta"]).read_text())
        v.update(_center_verdict(out, meta["product_center_rc"], float(meta.get("product_center_quality_px", 2.0))))
        v.update(_range_verdict(rng, s_rng, float(meta["range_km"])) if rng is not None else {})
        ell = out.get("ellipse") or {}
        a = (ell.get("semi_axes_px") or [out.get("radius_px")])[0]
        if a is not None:
            v["semi_major_px_times_range_km"] = float(a) * float(meta["range_km"])
    elif kind == "limb_trace":
        if "jupiter_truth" not in cache:
            cache["jupiter_truth"] = _jupiter_truth(out, fr["path"])
        t = cache["jupiter_truth"]
        v.update(_center_verdict(out, t["center_rc"], float(np.hypot(*t["spread_rc_px"]))))
        v.update(_range_verdict(rng, s_rng, out["spice"]["predicted"]["range_km"]) if rng is not None else {})
    z = [abs(v[k]) for k in ("center_mahalanobis", "range_z") if v.get(k) is not None]
    v["within_5_sigma"] = bool(all(x <= 5.0 for x in z)) if z else None
    return v


def summary_line(name: str, r: dict) -> str:
    out, v = r["answer"], r["verdict"]
    if out.get("status") != "ok":
        return f"{name:26s} {out.get('check', '?'):24s} {out.get('message', '')[:110]}"
    parts = [f"{name:26s} ok"]
    if "center_error_px" in v:
        parts.append(f"centre {v['center_error_px']:.2f} px (Mahalanobis {v.get('center_mahalanobis', float('nan')):.2f})")
    if v.get("range_error_frac") is not None:
        parts.append(f"range {100 * v['range_error_frac']:+.3f} % (z {v.get('range_z') or float('nan'):+.2f})")
    if v.get("within_5_sigma") is not None:
        parts.append("within 5 sigma" if v["within_5_sigma"] else "BEYOND 5 SIGMA")
    return "  ".join(parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=None, help="comma-separated frame names (default: all)")
    ap.add_argument("--out", default="real_frames")
    ap.add_argument("--figures", action="store_true", help="write the gallery (docs/validation/real_frames/)")
    a = ap.parse_args(argv)
    frames = _frames()
    if a.only:
        keep = set(a.only.split(","))
        frames = [f for f in frames if f["name"] in keep]
    rows, cache = {}, {}
    for fr in frames:
        cmd = fr.get("command", "locate")
        code, out, sec = run_command([cmd, str(fr["path"]), *fr["args"]])
        out.pop("selected_pixels_rc", None)
        rows[fr["name"]] = {"command": f"jaxlimb {cmd} {fr['path'].relative_to(DATA.resolve())} "
                                       + " ".join(x if not x.startswith("/") else Path(x).name for x in fr["args"]),
                            "exit_code": code, "seconds": sec, "answer": out, "verdict": judge(fr, out, cache)}
        print(summary_line(fr["name"], rows[fr["name"]]), flush=True)
    epic = [r["verdict"]["semi_major_px_times_range_km"] for n, r in rows.items()
            if n.startswith("epic") and n.endswith("_any_sigma") and "semi_major_px_times_range_km" in r["verdict"]]
    res = {"environment": environment(), "frames": rows, "jupiter_truth": cache.get("jupiter_truth"),
           "epic_radius_times_range_scatter": float(np.std(epic) / np.mean(epic)) if len(epic) > 1 else None,
           "n_ok": sum(r["answer"].get("status") == "ok" for r in rows.values()),
           "n_beyond_5_sigma": sum(r["verdict"].get("within_5_sigma") is False for r in rows.values())}
    if a.figures:
        from _real_frame_figures import gallery

        res["figures"] = gallery(frames, rows, Path(__file__).resolve().parents[1] / "docs" / "validation" / "real_frames",
                                 run_command)
    print(f"ok {res['n_ok']} of {len(rows)}; beyond 5 sigma: {res['n_beyond_5_sigma']}; EPIC radius x range scatter "
          f"{res['epic_radius_times_range_scatter']}")
    print(save(a.out, res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
