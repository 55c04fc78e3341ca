"""Which of ``locate``'s model-error terms sets its reported sigma: the same frames measured with the terms in turn.

Usage::

    .venv/bin/python benchmarks/model_error_terms.py [--body earth] [--family own] [--seeds 0,1,2,3,4,5]
                                                     [--out model_error_terms_earth_own]

``locate``'s covariance of a limb-profile fit is its noise-only bound (``covariance_noise``) plus the model-error
terms of :func:`jaxlimb.pipeline.profile.model_error.with_model_error`, each clipped to its positive part: the
sector sandwich (:func:`~jaxlimb.model_error.cluster_robust_covariance`) and the split witness
(:func:`~jaxlimb.pipeline.profile.model_error.split_witness`); the Earth's adds the consider term of an
unresolved glow (``EllipsoidOptions.unresolved_glow``).  Each frame of the independent renderer
(``moon_case`` / ``earth_case`` of ``--family`` drawn from ``default_rng(seed)``) is measured with: every term
(``all``, the default), the sandwich alone, the witness alone, neither (``none``), and, for the Earth, every term
but the glow's (``no_glow_consider``).  The terms are switched off by replacing the module's functions for the
run (an ablation, not an option of the package).  Per frame and variant: the sigma of the centre's row and
column and of the range (or radius), the noise-only sigma, and the error against the truth.  Results go to
``benchmarks/results/<out>.json``.
"""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import environment, save  # noqa: E402

VARIANTS = ("all", "sandwich", "witness", "none", "no_glow_consider")


@contextmanager
def terms(variant: str):
    """The model-error terms of ``variant`` (module docstring) for the duration of the block."""
    import jaxlimb.pipeline.profile.model_error as me

    split, sandwich = me.split_witness, me.cluster_robust_covariance

    def only_split(*a, **k):  # noqa: ANN002, ANN003, ANN202
        idx, W = split(*a, **k)
        return idx, W * (variant in ("all", "witness", "no_glow_consider"))

    def only_sandwich(J, r, groups):  # noqa: ANN001, ANN202
        C = sandwich(J, r, groups)
        return C if variant in ("all", "sandwich", "no_glow_consider") else np.zeros_like(C)  # C0 + [0 - C0]_+ = C0

    me.split_witness, me.cluster_robust_covariance = only_split, only_sandwich
    try:
        yield
    finally:
        me.split_witness, me.cluster_robust_covariance = split, sandwich


def measure(case, variant: str) -> dict:  # noqa: ANN001
    """``locate`` on ``case`` with the terms of ``variant``: sigmas, noise-only sigmas and errors."""
    from jaxlimb.imaging import Hints
    from jaxlimb.pipeline import LocateOptions, locate
    from jaxlimb.pipeline.options import EllipsoidOptions

    opt = LocateOptions(ellipsoid=EllipsoidOptions(unresolved_glow=None)) if variant == "no_glow_consider" else None
    with terms(variant):
        j = locate(case.image, case.camera, Hints.from_dict(case.hints), opt).to_json()
    C, N, t = j["covariance"], j["covariance_noise"], case.truth
    # the size: the range (an ellipsoid's answer) or the apparent radius, its covariance key and the truth's
    size, value, truth = (("range_km", j["range_km"], t.range_km) if "range_km" in C
                          else ("radius", j["radius_px"], t.apparent_radius_px))
    err_rc = np.asarray(j["center_rc"], float) - np.asarray(t.body_center_rc, float)
    keys = ("center_r", "center_c", size)
    return {"sigma": [C[k][k] ** 0.5 for k in keys], "sigma_noise": [N[k][k] ** 0.5 for k in keys],
            "error": [*err_rc.tolist(), float(value) - float(truth)], "keys": list(keys)}


def main(argv: list[str] | None = None) -> dict:
    from jaxlimb._jaxcache import start_jax

    start_jax()
    from jaxlimb.render.independent import earth_case, moon_case

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--body", choices=("moon", "earth"), default="earth")
    ap.add_argument("--family", default="own")
    ap.add_argument("--seeds", default="0,1,2,3,4,5")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    draw = earth_case if args.body == "earth" else moon_case
    variants = VARIANTS if args.body == "earth" else VARIANTS[:4]
    env = environment()  # the tree as the run starts
    frames = []
    for seed in (int(s) for s in args.seeds.split(",")):
        case = draw(args.family, np.random.default_rng(seed))
        row = {"seed": seed, **{v: measure(case, v) for v in variants}}
        frames.append(row)
        size = [f"{v} {row[v]['sigma'][2]:.4g}" for v in variants]
        print(f"seed {seed}: size error {row['all']['error'][2]:+.4g}, noise-only sigma {row['all']['sigma_noise'][2]:.4g},"
              f" sigma: {', '.join(size)}", flush=True)
    out = {"body": args.body, "family": args.family, "variants": list(variants), "frames": frames,
           "environment": env,
           "command": "python benchmarks/model_error_terms.py " + " ".join(argv if argv is not None else sys.argv[1:])}
    print(f"wrote {save(args.out or f'model_error_terms_{args.body}_{args.family}', out)}")
    return out


if __name__ == "__main__":
    main()
