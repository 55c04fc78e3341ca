"""Where an albedo pattern's bias of ``locate``'s centre comes from: one albedo-invariance scene under ablations.

The scene is one of ``benchmarks/albedo_invariance.py``'s (the same renders, keys and draws: the independent
renderer's ``spots`` maps over one noise draw, and the uniform albedo over several noise draws), located with
``locate``'s defaults and with one part of its profile changed at a time:

* ``default``: as shipped;
* ``no_field``: the least-squares profile, without the refit under the albedo field;
* ``L_held``: the ellipsoid's lunar-Lambert weight held at the Lambert truth of the Earth's renders (``L = 0``)
  instead of estimated;
* ``free_field``: the field's correlation length 4 deg (nodes 2 deg apart, finer than the spots) and its amplitude
  1 instead of the restricted-likelihood estimate: the albedo near the limb all but free.

Reported per variant and albedo kind: the mean error of the centre (row, col; its norm is the albedo-invariance
benchmark's mean error), the rms spread about it, the mean error of the limb ellipse's semi-axes (a bias of the
apparent size), the mean NEES and the median sigma; and every answer.

Run::

    python benchmarks/albedo_bias.py --cache build/albedo_renders      # -> results/albedo_bias.json
    python benchmarks/albedo_bias.py --scene 3 --draws 20 --noise 8 --variants default,no_field
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import environment, save  # noqa: E402
from albedo_invariance import SCENES, measure, scene_case, summary  # noqa: E402

VARIANTS = ("default", "no_field", "L_held", "free_field")


def variant(name: str) -> contextlib.ExitStack:
    """The patches of one variant (module docstring), as a context."""
    import jaxlimb.pipeline.ellipsoid.profile as ellipsoid_profile
    import jaxlimb.pipeline.profile.albedo_field as albedo_field
    import jaxlimb.pipeline.profile.albedo_prior as albedo_prior
    import jaxlimb.pipeline.sphere.refit as sphere_refit
    from jaxlimb.models import PROFILE_FIXED

    stack = contextlib.ExitStack()
    if name == "no_field":
        stack.enter_context(mock.patch.object(ellipsoid_profile, "with_albedo_field", lambda frame, answer, shape: answer))
        stack.enter_context(mock.patch.object(sphere_refit, "with_albedo_field", lambda frame, answer: answer))
    elif name == "L_held":
        stack.enter_context(mock.patch.object(ellipsoid_profile, "PROFILE_HELD", PROFILE_FIXED))
        stack.enter_context(mock.patch.object(ellipsoid_profile, "lunar_lambert_weight", lambda phase: 0.0))
    elif name == "free_field":
        estimate = albedo_field.residual_field

        def free(*args, **kw):  # noqa: ANN002, ANN003, ANN202
            s2, _, ell, U, GU = estimate(*args, **kw)
            return s2, 1.0, ell, U, GU

        for mod in (albedo_prior, albedo_field):
            stack.enter_context(mock.patch.object(mod, "ELL_DEG", (4.0,)))
        stack.enter_context(mock.patch.object(albedo_field, "residual_field", free))
    elif name != "default":
        raise SystemExit(f"unknown variant {name!r}; one of {', '.join(VARIANTS)}")
    return stack


def main(argv: list[str] | None = None) -> dict:
    import jax
    from tqdm import tqdm

    jax.config.update("jax_enable_x64", True)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", type=int, default=2, help="index of albedo_invariance.SCENES (default 2: the Earth, "
                                                          "40 000 km)")
    ap.add_argument("--draws", type=int, default=8, help="spots draws (default 8)")
    ap.add_argument("--noise", type=int, default=4, help="noise draws of the uniform albedo (default 4)")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--cache", type=Path, default=None, help="directory keeping the renders (albedo_invariance's)")
    args = ap.parse_args(argv)
    body, range_km, phase = SCENES[args.scene]

    cases = {"spots": [scene_case(args.cache, body, range_km, phase, "spots", a, 0) for a in range(1, args.draws + 1)],
             "uniform": [scene_case(args.cache, body, range_km, phase, "uniform", 0, n) for n in range(args.noise)]}
    names = args.variants.split(",")
    out = {"environment": environment(), "scene": {"body": body, "range_km": range_km, "phase_deg": phase},
           "draws": args.draws, "noise_draws": args.noise, "variants": {}}
    with tqdm(total=len(names) * (args.draws + args.noise), desc="albedo bias") as bar:
        for name in names:
            out["variants"][name] = {}
            with variant(name):
                for kind, cs in cases.items():
                    rows = []
                    for c in cs:
                        rows.append(measure(c))
                        bar.update()
                    out["variants"][name][kind] = {"summary": summary(rows), "rows": rows}
    for name, v in out["variants"].items():
        for kind, s in ((k, x["summary"]) for k, x in v.items()):
            ax = s.get("mean_axes_error_px") or [math.nan, math.nan]
            print(f"{name:10s} {kind:7s} {s['n_ok']}/{s['n']} mean error {s.get('mean_error_px', math.nan):.3f} px "
                  f"{np.round(s.get('mean_error_rc', [math.nan] * 2), 3)} spread {s.get('spread_px', math.nan):.3f} "
                  f"axes {np.round(ax, 3)} NEES {s.get('mean_nees', math.nan):.2f} "
                  f"sigma {s.get('median_sigma_px', math.nan):.3f}")
    save("albedo_bias", out)
    return out


if __name__ == "__main__":
    main()
