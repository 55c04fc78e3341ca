"""``locate`` on the sunlit Earth nearly full from deep space (DSCOVR/EPIC-like), independent renders.

Usage::

    .venv/bin/python benchmarks/earth_full_disc.py [--n N] [--seed S] [--families own,clouds,...] [--cache DIR]
                                                   [--out NAME]

Scenes: :func:`jaxlimb.render.independent.earth_full_disc_case` -- 1.5 million km, phase 4-12 deg, the
disc 760-900 px across in a 1080^2 frame, the photometry / albedo / glow / PSF / sensor of each family of
``benchmarks/families.py`` that applies (``own`` lunar-Lambert, ``lambert``, ``clouds`` Lambert x ocean,
continents and clouds, ``glow``, ``jpeg``, ``combined``).  At this phase a Lambert Earth darkens to zero
at its limb and the strongest edges are cloud edges inside the disc: the hard case of real full-disc
views from deep space (1080^2, camera and range prior), where a plain limb detector stops at Check 2.
``locate`` gets the camera and the hints (Sun direction, range prior 5 % off, ``atmosphere_km = 0``),
once with ``R_body_to_camera`` and once without (``earth`` / ``earth_noR`` rows).  Reported as in
``benchmarks/families.py`` (centre median / p90 / max px, range error, NEES, typed failures, non-physical
``ok`` answers).  Writes ``benchmarks/results/<out>.json`` (default ``earth_full_disc``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from families import measure, print_table, summarise  # noqa: E402

RENDER_VERSION = 1  # bump when the renderer's output changes (cache key)


def _case(family: str, idx: int, seed: int, cache: Path | None):
    from _common import cached

    from jaxlimb.render.independent import EARTH_FULL_DISC_FAMILIES, earth_full_disc_case

    rng = np.random.default_rng([seed, 2, EARTH_FULL_DISC_FAMILIES.index(family), idx])
    return cached(cache, f"earthdisc_{family}_{idx}_s{seed}_v{RENDER_VERSION}.pkl", lambda: earth_full_disc_case(family, rng))


def run(families, n: int, seed: int, cache: Path | None, progress=print) -> dict[str, Any]:
    records: dict[str, dict[str, list]] = {}
    for fam in families:
        for i in range(n):
            case = _case(fam, i, seed, cache)
            for name, hints in (("earth", case.hints),
                                ("earth_noR", {k: v for k, v in case.hints.items() if k != "R_body_to_camera"})):
                rec = measure(case, hints)
                rec["meta"] = case.meta
                records.setdefault(name, {}).setdefault(fam, []).append(rec)
                progress(f"{name:9s} {fam:9s} {i}: {rec['status']} "
                         + (f"{rec['center_err_px']:.3f} px, range {rec.get('range_err_pct', float('nan')):+.3f} %"
                            if rec["status"] == "ok" else f"{rec['check']}: {rec['message'][:120]}"))
    return {"records": records, "summary": {b: {f: summarise(r) for f, r in fams.items()} for b, fams in records.items()}}


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from _common import environment, save

    from jaxlimb.render.independent import EARTH_FULL_DISC_FAMILIES

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=3, help="frames per family (default 3)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--families", default=None, help="comma-separated subset of " + ",".join(EARTH_FULL_DISC_FAMILIES))
    ap.add_argument("--cache", type=Path, default=None, help="directory to keep rendered frames in between runs")
    ap.add_argument("--out", default="earth_full_disc")
    a = ap.parse_args(argv)
    fams = [f for f in EARTH_FULL_DISC_FAMILIES if a.families is None or f in a.families.split(",")]
    t0 = time.perf_counter()
    res = run(fams, a.n, a.seed, a.cache)
    print_table(res["summary"])
    out = {"args": {"n": a.n, "seed": a.seed, "families": fams}, "environment": environment(),
           "wall_s": time.perf_counter() - t0, **res}
    print(f"saved {save(a.out, out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
