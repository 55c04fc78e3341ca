"""Warm ``locate`` per 1944x2592 Moon frame (budget: the default path <= 150 ms after warm-up).

Two frame sets, each timed in its own fresh process after one warm-up pass, CPU and wall time per frame:

* ``default``: six frames of ``cli_speed.py``'s Moon generator (150 000 km, 45 deg, lunar-Lambert, 8 bit);
* ``maria``: the six ``maria`` frames of ``families.py`` (independent renderer; they take the patchy-sector
  refit, :func:`jaxlimb.pipeline.profile.patchy.downweight_patchy_sectors`).

Baselines measured in the same run: the same frames with the patchy-sector refit switched off
(``no_patchy_refit``) and with the refit under the albedo field switched off (``no_albedo_field``,
:func:`jaxlimb.pipeline.profile.albedo_field.with_albedo_field`), processes alternated so that load falls on all
alike; the JSON keeps every round and the minimum.

    python benchmarks/warm_locate.py [--rounds 4] [--cache /tmp/fam_cache]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

from _common import environment, save

CHILD = r"""
import json, os, sys, time
import numpy as np, jax
jax.config.update("jax_enable_x64", True)
variant, frame_set, cache, bench = sys.argv[1:5]
sys.path.insert(0, bench)
import jaxlimb.pipeline.profile.fit as pf
if variant == "no_patchy_refit":
    pf.downweight_patchy_sectors = lambda frame, rr, solver, system=None: rr
if variant == "no_albedo_field":
    import jaxlimb.pipeline.sphere.predicted as sp, jaxlimb.pipeline.sphere.refit as sr
    sr.with_albedo_field = sp.with_albedo_field = lambda frame, answer: answer
from jaxlimb.imaging import Hints
from jaxlimb.pipeline import locate
frames = []
if frame_set == "default":
    from jaxlimb.geometry.camera import Camera
    from jaxlimb.render import RenderOptions, moon_scene, render_body
    cam = Camera.default()
    for i in range(6):
        sc = moon_scene(150_000.0 + 1500 * i, 45.0, center_rc=(900.0 + 3 * i, 1400.0 - 2 * i), camera=cam,
                        sun_angle_deg=30.0)
        img, truth = render_body(sc, cam, RenderOptions(reflectance="lunar-lambert", psf_sigma_px=1.0, bit_depth=8),
                                 seed=i)
        h = Hints.from_dict({"body": "moon", "sun_dir_camera": [float(v) for v in truth.sun_dir_cam]})
        frames.append((np.asarray(img).astype(np.uint8), cam, h))
else:
    import families
    from pathlib import Path
    for i in range(6):
        c = families.family_case("moon", "maria", i, 2026, Path(cache))
        frames.append((c.image, c.camera, Hints.from_dict(c.hints)))
for img, cam, h in frames:
    locate(img, cam, h)
cpu, wall = [], []
for _ in range(3):
    c0, w0 = time.process_time(), time.perf_counter()
    for img, cam, h in frames:
        locate(img, cam, h)
    cpu.append(1e3 * (time.process_time() - c0) / len(frames))
    wall.append(1e3 * (time.perf_counter() - w0) / len(frames))
print(json.dumps({"cpu_ms": sorted(cpu)[1], "wall_ms": sorted(wall)[1], "load": os.getloadavg()[0]}))
"""


VARIANTS = ("head", "no_patchy_refit", "no_albedo_field")


def _one(variant: str, frame_set: str, cache: str) -> dict:
    """One fresh process: warm ``locate`` on one frame set (median of 3 passes after a warm-up)."""
    bench = str(Path(__file__).resolve().parent)
    out = subprocess.run([sys.executable, "-c", CHILD, variant, frame_set, cache, bench], capture_output=True,
                         text=True, check=False)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise SystemExit(f"warm_locate: the {variant}/{frame_set} process failed: {out.stderr.strip()[-400:]}")
    return json.loads(lines[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=4, help="alternating rounds per variant (default 4)")
    ap.add_argument("--cache", default="/tmp/fam_cache", help="families.py frame cache (rendered if missing)")
    args = ap.parse_args()
    rounds: dict[str, list[dict]] = {}
    for _ in range(args.rounds):
        for frame_set in ("default", "maria"):
            for variant in VARIANTS:
                key = f"{frame_set}/{variant}"
                rounds.setdefault(key, []).append(_one(variant, frame_set, args.cache))
                print(key, rounds[key][-1], flush=True)
    best = {k: {"cpu_ms": min(r["cpu_ms"] for r in v), "wall_ms": min(r["wall_ms"] for r in v)} for k, v in rounds.items()}
    for fs in ("default", "maria"):
        h = best[f"{fs}/head"]
        for v in VARIANTS[1:]:
            best[f"{fs}/ratio_wall_{v}"] = round(h["wall_ms"] / best[f"{fs}/{v}"]["wall_ms"], 3)
        print(f"{fs}: {h['wall_ms']:.1f} ms wall, {h['cpu_ms']:.1f} ms CPU per frame; "
              + ", ".join(f"{best[f'{fs}/ratio_wall_{v}']}x {v}" for v in VARIANTS[1:]))
    path = save("warm_locate", {"environment": environment(), "args": vars(args), "best": best, "rounds": rounds,
                                "budget_ms": 150.0, "load_end": os.getloadavg()[0]})
    print("saved", path)


if __name__ == "__main__":
    main()
