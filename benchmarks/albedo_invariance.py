"""Albedo invariance: does the albedo pattern move ``locate``'s centre more than the noise does?

Each scene (body, range, phase) is rendered by the independent renderer (:func:`jaxlimb.render.independent.
families.albedo_case`) with the same geometry, PSF and sensor, once with a uniform albedo under ``--noise``
different noise draws, and once per albedo draw (``--draws`` maps of the ``spots`` kind: overlapping Gaussian spots
9-26 deg across, 15-35 % deep, with a +-4 % gradient) under one noise draw.  ``locate`` runs with the hints a filter
has (body, Sun direction, a range prior 3 % off; the Earth's attitude) and its defaults.  Reported per scene:

* ``noise``: the centre's error over the noise draws (uniform albedo): mean, rms spread about the mean, NEES;
* ``albedo``: the same over the albedo draws (one noise draw), and ``spread_ratio`` = albedo spread / noise spread
  (the target is <= 1.2: the albedo adds no more scatter than the noise);
* every answer's error, sigma and NEES, and the typed failures.

Run::

    python benchmarks/albedo_invariance.py --cache build/albedo_renders       # -> results/albedo_invariance.json
    python benchmarks/albedo_invariance.py --cache build/albedo_renders --scenes 0,1 --profile albedo-field

(renders are the slow part, ~2-40 s each; ``--cache`` keeps them for the next run).  A run of some scenes keeps the
results file's other scenes (same draws and profile), each scene with the environment it was measured in.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import RESULTS, cached, environment, save  # noqa: E402

SCENES = (("moon", 150_000.0, 45.0), ("moon", 380_000.0, 90.0), ("earth", 40_000.0, 35.0), ("earth", 380_000.0, 50.0))


def scene_case(cache: Path | None, body: str, range_km: float, phase_deg: float, kind: str, albedo_seed: int,
               noise_seed: int):  # type: ignore[no-untyped-def]
    """One render of a scene (:func:`~jaxlimb.render.independent.families.albedo_case`), kept in ``cache`` under the
    key the albedo benchmarks share."""
    from jaxlimb.render.independent.families import albedo_case

    key = f"{body}_{int(range_km)}_{int(phase_deg)}_{kind}_a{albedo_seed}_n{noise_seed}.pkl"
    return cached(cache, key, lambda: albedo_case(body, range_km, phase_deg, kind, albedo_seed, noise_seed))


def measure(case, profile: str = "auto") -> dict:  # type: ignore[no-untyped-def]
    """One ``locate`` answer against the truth: the centre's error, sigma, NEES and CRLB, and the error of the limb's
    semi-axes (the radius's for a circle); a typed failure as its check."""
    from jaxlimb.analysis.pipeline_study import measurement_errors
    from jaxlimb.errors import CheckFailed
    from jaxlimb.geometry.hints import Hints
    from jaxlimb.pipeline import LocateOptions, locate

    try:
        m = locate(case.image, case.camera, Hints.from_dict(case.hints), LocateOptions(profile=profile))
    except CheckFailed as e:
        return {"status": "failed", "check": e.check}
    r = measurement_errors(m, case.truth)  # the pipeline study's numbers of one answer
    crlb = [r["crlb_row"], r["crlb_col"]] if "crlb_row" in r else None
    out = {"status": "ok", "error_rc": [r["row"], r["col"]], "error_px": float(np.hypot(r["row"], r["col"])),
           "sigma_rc": [r["sigma_row"], r["sigma_col"]], "nees": r["nees"], "crlb_rc": crlb}
    if m.ellipse is not None:
        out["axes_error_px"] = (np.array(m.ellipse.semi_axes_px) - np.array(case.truth.semi_axes_px)).tolist()
    elif "radius" in r:
        out["axes_error_px"] = [r["radius"]] * 2
    return out


def summary(rows: list[dict]) -> dict:
    """The answers' mean error (row, col) and its norm, median, p90, rms spread about the mean, mean NEES, median
    sigma, and the mean semi-axes error when measured; the typed failures."""
    ok = [r for r in rows if r["status"] == "ok"]
    out: dict = {"n": len(rows), "n_ok": len(ok), "failures": sorted(r["check"] for r in rows if r["status"] != "ok")}
    if not ok:
        return out
    e = np.array([r["error_rc"] for r in ok])
    mean = e.mean(axis=0)
    out.update(mean_error_rc=mean.tolist(), mean_error_px=float(np.hypot(*mean)),
               median_error_px=float(np.median([r["error_px"] for r in ok])),
               p90_error_px=float(np.percentile([r["error_px"] for r in ok], 90)),
               spread_px=float(math.sqrt(np.mean(np.sum((e - mean) ** 2, axis=1)) / 2.0)) if len(ok) > 1 else None,
               mean_nees=float(np.mean([r["nees"] for r in ok])),
               median_sigma_px=float(np.median([np.mean(r["sigma_rc"]) for r in ok])))
    axes = [r["axes_error_px"] for r in ok if "axes_error_px" in r]
    if axes:
        out["mean_axes_error_px"] = np.mean(axes, axis=0).tolist()
    return out


def run_scene(body: str, range_km: float, phase_deg: float, n_noise: int, n_draws: int, cache: Path | None,
              progress, profile: str = "auto") -> dict:  # type: ignore[no-untyped-def]
    def case(kind: str, a: int, n: int):  # type: ignore[no-untyped-def]
        return scene_case(cache, body, range_km, phase_deg, kind, a, n)

    noise, albedo = [], []
    for n in range(n_noise):
        noise.append({"noise_seed": n, **measure(case("uniform", 0, n), profile)})
        progress.update()
    for a in range(1, n_draws + 1):
        albedo.append({"albedo_seed": a, **measure(case("spots", a, 0), profile)})
        progress.update()
    s_noise, s_albedo = summary(noise), summary(albedo)
    ratio = (s_albedo["spread_px"] / s_noise["spread_px"]
             if s_noise.get("spread_px") and s_albedo.get("spread_px") else None)
    return {"body": body, "range_km": range_km, "phase_deg": phase_deg, "noise": s_noise, "albedo": s_albedo,
            "spread_ratio": ratio, "noise_rows": noise, "albedo_rows": albedo}


def with_other_scenes(name: str, out: dict) -> dict:
    """``out`` with the scenes of ``results/<name>.json`` that it did not measure, when that file has the same draws
    and profile: a run of some scenes does not drop the others' results."""
    path = RESULTS / f"{name}.json"
    if not path.exists():
        return out
    old = json.loads(path.read_text())
    same = ("profile", "noise_draws", "albedo_draws")
    if any(old.get(k) != out[k] for k in same):
        return out

    def key(s: dict) -> tuple:
        return s["body"], s["range_km"], s["phase_deg"]

    new, order = {key(s) for s in out["scenes"]}, {sc: i for i, sc in enumerate(SCENES)}
    scenes = [s for s in old["scenes"] if key(s) not in new] + out["scenes"]
    return {**out, "scenes": sorted(scenes, key=lambda s: order.get(key(s), len(SCENES)))}


def main(argv: list[str] | None = None) -> dict:
    import jax
    from tqdm import tqdm

    jax.config.update("jax_enable_x64", True)  # estimation runs in float64

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--noise", type=int, default=8, help="noise draws of the uniform-albedo scene (default 8)")
    ap.add_argument("--draws", type=int, default=20, help="albedo draws (default 20)")
    ap.add_argument("--scenes", default="all", help="comma-separated scene indices of SCENES (default all)")
    ap.add_argument("--cache", type=Path, default=None, help="directory keeping the renders")
    ap.add_argument("--profile", choices=("auto", "albedo-field"), default="auto",
                    help="locate's profile (default auto); albedo-field writes results/albedo_invariance_field.json")
    args = ap.parse_args(argv)
    idx = range(len(SCENES)) if args.scenes == "all" else [int(i) for i in args.scenes.split(",")]
    out = {"environment": environment(), "profile": args.profile, "noise_draws": args.noise, "albedo_draws": args.draws,
           "scenes": []}
    with tqdm(total=len(idx) * (args.noise + args.draws), desc="albedo invariance") as bar:
        for i in idx:
            out["scenes"].append({**run_scene(*SCENES[i], args.noise, args.draws, args.cache, bar, args.profile),
                                  "environment": out["environment"]})
    for s in out["scenes"]:
        a, n = s["albedo"], s["noise"]
        print(f"{s['body']:5s} {s['range_km']:>9.0f} km {s['phase_deg']:>4.0f} deg: noise mean {n.get('mean_error_px', 0):.3f}"
              f" spread {n.get('spread_px') or 0:.3f} NEES {n.get('mean_nees', 0):.2f} | albedo median "
              f"{a.get('median_error_px', 0):.3f} p90 {a.get('p90_error_px', 0):.3f} mean {a.get('mean_error_px', 0):.3f} "
              f"spread {a.get('spread_px') or 0:.3f} NEES {a.get('mean_nees', 0):.2f} ratio {s['spread_ratio'] or float('nan'):.1f}"
              f" failures {a['failures']}")
    name = "albedo_invariance" if args.profile == "auto" else "albedo_invariance_field"
    save(name, out := with_other_scenes(name, out))
    return out


if __name__ == "__main__":
    main()
