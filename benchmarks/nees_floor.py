"""Mean NEES of the centre per family under candidate specification floors, from a results JSON of
``benchmarks/families.py`` (its ``ok`` records keep the reported 2x2 centre covariance ``cov_rc``).

    python benchmarks/nees_floor.py benchmarks/results/families_earth.json [--floors 0,0.005,0.0075,0.01]

Each covariance has its eigenvalues below ``floor^2`` raised to it, ``C + [floor^2 I - C]_+`` (as
``EllipsoidOptions.center_floor_px`` does to the ellipse centre), and the NEES ``e^T C^-1 e`` of the frame's centre error ``e`` is averaged per family.  Run it on
a ``families.py --center-floor 0`` result to choose the floor on one seed, and check the choice on another.
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def floored_nees(rec: dict, floor: float) -> float:
    """NEES of one ``ok`` record with its centre covariance floored at ``floor`` px in every direction."""
    from jaxlimb.model_error import with_model_error

    C, e = np.array(rec["cov_rc"], float), np.array(rec["err_rc"], float)
    return float(e @ np.linalg.solve(with_model_error(C, floor * floor * np.eye(2)), e))


def table(results: dict, body: str, floors: list[float]) -> dict[str, list[float]]:
    """``{family: [mean NEES at each floor]}`` over the ``ok`` records of ``body``."""
    out = {}
    for fam, recs in results["records"].get(body, {}).items():
        ok = [r for r in recs if r.get("status") == "ok" and r.get("cov_rc") is not None]
        if ok:
            out[fam] = [float(np.mean([floored_nees(r, f) for r in ok])) for f in floors]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results")
    ap.add_argument("--body", default="earth")
    ap.add_argument("--floors", default="0,0.005,0.0075,0.01,0.015")
    a = ap.parse_args(argv)
    floors = [float(f) for f in a.floors.split(",")]
    with open(a.results) as fh:
        res = json.load(fh)
    print(f"{'family':10s} " + " ".join(f"{f:>8.4f}" for f in floors) + "   (mean NEES; floor px)")
    for fam, row in table(res, a.body, floors).items():
        print(f"{fam:10s} " + " ".join(f"{v:8.2f}" for v in row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
